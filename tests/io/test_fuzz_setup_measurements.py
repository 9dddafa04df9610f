"""Fuzzing the setup and measurement loaders, directly and through the command line.

Whatever the file, the loader either returns a usable object or raises a PkmcalError whose
message is one line starting with the file's name; the CLI exits with 0 (and writes its
output) or 2 (one ``pkmcal: error:`` line on stderr, no traceback, no output file).
About 3 000 generated files in all (plus the machine-file fuzz of test_fuzz_loaders.py)."""

from __future__ import annotations

import copy

import numpy as np
import yaml
from click.testing import CliRunner
from helpers import (
    assert_ok_or_user_error,
    cells,
    csv_texts,
    dump_yaml,
    fuzz_file,
    fuzz_settings,
    keys,
    mutate,
    structures,
)
from hypothesis import given
from hypothesis import strategies as st

from pkmcal.cli.main import cli
from pkmcal.errors import PkmcalError
from pkmcal.io.measurements import load_measurements
from pkmcal.io.setup_file import builtin_setup, load_setup
from pkmcal.mechanisms.library import stewart_prototype
from pkmcal.sensors.base import MeasurementSetup

CHEAP = fuzz_settings(500)
CLI = fuzz_settings(500)

VALID_SETUPS = [yaml.safe_load(t) for t in (
    """
sensor: indicators
description: three dial indicators
indicators: [[40, 0], [-20, 34.641], [-20, -34.641]]
plane_offset: 10.0
zero: [0, 0, 0]
free: [zero1]
noise: {reading: 0.01, actuator: 0.005}
""", """
sensor: full-pose
world: {x: 0, y: 0, z: 0, a: 0, b: 0, c: 0}
tool: {x: 0, y: 0, z: 25}
noise: {distribution: uniform, position: 0.025, orientation: 0.001, actuator: [0.01, 0.01, 0.01, 0.01, 0.01, 0.01]}
""", """
sensor: position
target: {x: 0, y: 0, z: 30}
noise: {reading: 0.01, actuator: 0.005}
""")]

SETUP_KEYS = st.one_of(keys, st.sampled_from(["sensor", "indicators", "plane_offset", "zero", "world", "tool",
                                              "target", "free", "noise", "reading", "actuator", "distribution",
                                              "orientation_deg", "simulation", "stiffness", "description"]))
SETUP_SCALARS = st.sampled_from(["indicators", "full-pose", "position", "planar-tool", "gaussian", "uniform",
                                 "zero1", "world.x", "tool.c", "nan", ".inf", -1, 0, 1e400, None, True, [], {}])


@st.composite
def mutated_setups(draw):
    data = copy.deepcopy(draw(st.sampled_from(VALID_SETUPS)))
    return mutate(draw, data, st.one_of(structures, SETUP_SCALARS), SETUP_KEYS,
                  actions=("replace", "replace", "delete", "insert"))


def _check_setup_file(path) -> None:
    try:
        s = load_setup(path)
    except PkmcalError as exc:
        msg = str(exc)
        assert msg.startswith(str(path)) and "\n" not in msg, msg
        return
    assert isinstance(s, MeasurementSetup)


# -- setup files ---------------------------------------------------------------------------------

def test_valid_setups_load(tmp_path):
    for k, data in enumerate(VALID_SETUPS):
        (tmp_path / f"s{k}.yaml").write_text(dump_yaml(data))
        assert isinstance(load_setup(tmp_path / f"s{k}.yaml"), MeasurementSetup)


@CHEAP
@given(st.one_of(mutated_setups(), structures))
def test_mutated_setup_files(tmp_path_factory, data):
    path = fuzz_file(tmp_path_factory, "setup.yaml", dump_yaml(data))
    _check_setup_file(path)


@CHEAP
@given(st.one_of(st.binary(max_size=200), st.text(max_size=200).map(lambda t: t.encode("utf-8", "surrogatepass"))))
def test_random_bytes_setup(tmp_path_factory, blob):
    path = fuzz_file(tmp_path_factory, "setup.yaml", blob)
    _check_setup_file(path)


@CLI
@given(mutated_setups())
def test_cli_on_mutated_setups(tmp_path_factory, data):
    d = tmp_path_factory.mktemp("cli")
    (d / "setup.yaml").write_text(dump_yaml(data), encoding="utf-8")
    (d / "poses.csv").write_text(POSES_CSV)
    res = CliRunner().invoke(cli, ["identifiability", "stewart-prototype", "--setup", str(d / "setup.yaml"),
                                   "--poses", str(d / "poses.csv"), "--json"])
    assert_ok_or_user_error(res)


# -- measurement files ---------------------------------------------------------------------------

POSES_CSV = "x,y,z,a,b,c\n0,0,315,0,0,0\n5,-3,318,1,-1,2\n-4,6,312,-2,1,-3\n3,3,316,0.5,2,4\n"
MACHINE = stewart_prototype()
SETUP = builtin_setup("indicators-prototype")
# four poses measured with the indicators (readings mm); a valid file, mutated below
_LAM = MACHINE.ik(np.array([[0, 0, 315, 0, 0, 0], [5, -3, 318, *np.deg2rad([1, -1, 2])],
                            [-4, 6, 312, *np.deg2rad([-2, 1, -3])], [3, 3, 316, *np.deg2rad([0.5, 2, 4])]]))
VALID_MEAS = [["# units: length=mm, angle=deg"],
              [f"lambda{i}" for i in range(1, 7)] + ["d1", "d2", "d3", "note"]]
for _k, _row in enumerate(_LAM):
    VALID_MEAS.append([repr(float(v)) for v in _row] + [repr(300.0 + _k), repr(301.0 - _k), repr(299.5 + _k), "ok"])


@st.composite
def mutated_measurements(draw):
    rows = [list(r) for r in VALID_MEAS]
    for _ in range(draw(st.integers(1, 4))):
        r = draw(st.integers(0, len(rows) - 1))
        action = draw(st.sampled_from(["cell", "cell", "header", "drop_cell", "add_cell", "drop_row", "dup_row",
                                       "units", "junk"]))
        if action == "cell" and rows[r]:
            rows[r][draw(st.integers(0, len(rows[r]) - 1))] = draw(cells)
        elif action == "header" and len(rows) > 1 and rows[1]:
            rows[1][draw(st.integers(0, len(rows[1]) - 1))] = draw(st.one_of(
                st.sampled_from(["lambda1", "l1", "d1", "D2", "λ3", "cmd_x", "x", "", "note", "lambda_7"]),
                st.text(max_size=5)))
        elif action == "drop_cell" and rows[r]:
            del rows[r][draw(st.integers(0, len(rows[r]) - 1))]
        elif action == "add_cell":
            rows[r].append(draw(cells))
        elif action == "drop_row":
            del rows[r]
        elif action == "dup_row":
            rows.insert(r, list(rows[r]))
        elif action == "units":
            rows.insert(0, [draw(st.sampled_from(["# units: length=m", "# units: length=furlong", "# units: angle=rad",
                                                  "# units: length", "#units: length=in, angle=deg"]))])
        else:
            rows.insert(r, [draw(st.text(max_size=20))])
        if not rows:
            break
    sep = draw(st.sampled_from(["\n", "\r\n"]))
    return sep.join(",".join(r) for r in rows) + sep


def _check_measurements(path) -> None:
    try:
        m = load_measurements(path, MACHINE, SETUP)
    except PkmcalError as exc:
        msg = str(exc)
        assert msg.startswith(str(path)) and "\n" not in msg, msg
        return
    assert m.actuators.shape == (len(m), 6) and m.readings.shape == (len(m), 3) and len(m) > 0
    assert np.all(np.isfinite(m.actuators)) and np.all(np.isfinite(m.readings))


def test_valid_measurement_base_loads(tmp_path):
    (tmp_path / "m.csv").write_text("\n".join(",".join(r) for r in VALID_MEAS) + "\n")
    m = load_measurements(tmp_path / "m.csv", MACHINE, SETUP)
    np.testing.assert_array_equal(m.actuators, _LAM)


@CHEAP
@given(st.one_of(mutated_measurements(), csv_texts()))
def test_mutated_measurement_files(tmp_path_factory, text):
    path = fuzz_file(tmp_path_factory, "meas.csv", text)
    _check_measurements(path)


@CHEAP
@given(st.binary(max_size=300))
def test_random_bytes_measurements(tmp_path_factory, blob):
    path = fuzz_file(tmp_path_factory, "meas.csv", blob)
    _check_measurements(path)


@CLI
@given(mutated_measurements())
def test_cli_identify_on_mutated_measurements(tmp_path_factory, text):
    d = tmp_path_factory.mktemp("cli")
    (d / "meas.csv").write_text(text, encoding="utf-8")
    out = d / "cal.yaml"
    res = CliRunner().invoke(cli, ["identify", "stewart-prototype", str(d / "meas.csv"), "--setup",
                                   "indicators-prototype", "-o", str(out), "--fix", "auto"])
    assert_ok_or_user_error(res, out)
    if res.exit_code == 0:
        assert out.exists()
