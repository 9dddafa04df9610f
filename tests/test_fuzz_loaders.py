"""Fuzzing the loaders: whatever the bytes, a machine file or CSV table either loads or raises
a PkmcalError with a one-line message (the CLI: exit code 2), never another exception."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pkmcal.cli.main import cli
from pkmcal.errors import PkmcalError
from pkmcal.io import machine_from_text, read_machine_file, read_table
from pkmcal.io.tables import LENGTH_COLUMNS, READING_COLUMNS
from pkmcal.mechanisms.base import Mechanism

FUZZ = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                       HealthCheck.too_slow])

VALID = yaml.safe_load("""
name: fuzz
legs:
  - {base: [-152.5, 0, 0], platform: [-60.622, 35, 0], offset: 305.0, stroke: [0, 50]}
  - {base: [-132.068, -76.25, 0], platform: [-35, -60.622, 0], offset: 305.0, stroke: [0, 50]}
  - {base: [76.25, -132.068, 0], platform: [0, -70, 0], offset: 305.0, stroke: [0, 50]}
  - {base: [132.068, -76.25, 0], platform: [70, 0, 0], offset: 305.0, stroke: [0, 50]}
  - {base: [76.25, 132.068, 0], platform: [60.622, 35, 0], offset: 305.0, stroke: [0, 50]}
  - {base: [0, 152.5, 0], platform: [-35, 60.622, 0], offset: 305.0, stroke: [0, 50]}
limits: {u_joint_tilt: 45, s_joint_tilt: 29, leg_diameter: 36.1, singularity_margin: 0.01}
home: {x: 0, y: 0, z: 315, a: 0, b: 0, c: 0}
workspace: {x: [-10, 10], y: [-10, 10], z: [300, 330], a: [-5, 5], b: [-5, 5], c: [-30, 30]}
uncertainty: {parameters: [b1.x, L0_2], std: {b1.x: 0.02, L0_2: 0.05}, correlation: [[1, 0.5], [0.5, 1]]}
calibration: {method: ik-residual, n_poses: 30}
""")

scalars = st.one_of(
    st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=12),
    st.sampled_from(["nan", ".inf", "-.inf", "1e400", "b1.x", "hexapod", "", "0x10", "1_000", "~"]),
    st.floats(allow_nan=True, allow_infinity=True), st.integers(min_value=10**300, max_value=10**310),
)
keys = st.one_of(st.sampled_from(["name", "kind", "legs", "limits", "home", "workspace", "uncertainty", "base",
                                  "platform", "offset", "stroke", "base_axis", "std", "correlation", "covariance",
                                  "parameters", "x", "a", "u_joint_tilt", "calibration", "metadata"]),
                 st.text(max_size=6), st.integers(-3, 3))
structures = st.recursive(scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=7), st.dictionaries(keys, inner, max_size=6)), max_leaves=30)


def _dump(data) -> str:
    return yaml.dump(data, Dumper=getattr(yaml, "CSafeDumper", yaml.SafeDumper), allow_unicode=True, sort_keys=False)


def _check_machine_text(text: str) -> None:
    try:
        m = machine_from_text(text, "fuzz.yaml")
    except PkmcalError as exc:
        msg = str(exc)
        assert msg.startswith("fuzz.yaml") and "\n" not in msg
        return
    assert isinstance(m, Mechanism)


def _paths(obj, prefix=()):
    yield prefix
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _paths(v, prefix + (i,))


ALL_PATHS = [p for p in _paths(VALID) if p]


@st.composite
def mutated_machines(draw):
    data = copy.deepcopy(VALID)
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(ALL_PATHS))
        parent = data
        try:
            for part in path[:-1]:
                parent = parent[part]
            action = draw(st.sampled_from(["replace", "delete", "insert"]))
            if action == "replace" or not isinstance(parent, (dict, list)):
                parent[path[-1]] = draw(structures)
            elif action == "delete":
                del parent[path[-1]]
            elif isinstance(parent, list):
                parent.insert(path[-1], draw(structures))
            else:
                parent[draw(keys)] = draw(structures)
        except (KeyError, IndexError, TypeError):
            continue  # an earlier mutation removed this path
    return data


def test_valid_fuzz_base_loads():
    m = machine_from_text(yaml.safe_dump(VALID), "fuzz.yaml")
    assert m.name == "fuzz"


@FUZZ
@given(structures)
def test_random_yaml_structures(data):
    _check_machine_text(_dump(data))


@FUZZ
@given(mutated_machines())
def test_mutated_machine_files(data):
    _check_machine_text(_dump(data))


@FUZZ
@given(st.text(max_size=200))
def test_random_text_machine(text):
    _check_machine_text(text)


@FUZZ
@given(st.binary(max_size=200))
def test_random_bytes_machine(tmp_path_factory, blob):
    path = tmp_path_factory.mktemp("m") / "fuzz.yaml"
    path.write_bytes(blob)
    try:
        read_machine_file(path)
    except PkmcalError as exc:
        assert str(exc).startswith(str(path)) and "\n" not in str(exc)


# -- CSV -----------------------------------------------------------------------------------------

cells = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr), st.integers().map(str),
    st.sampled_from(["", " ", "nan", "inf", "-inf", "abc", '"1"', '"a,b"', "1e400", "1_0", "--1", "#", "λ1", "0x1"]),
    st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=6),
)
names = st.one_of(st.sampled_from(list("xyzabc") + list(READING_COLUMNS) + list(LENGTH_COLUMNS)
                                  + ["X", "λ2", "L_3", "note", "", "# units: length=m"]), st.text(max_size=5))


@st.composite
def csv_texts(draw):
    header = draw(st.lists(names, min_size=0, max_size=10))
    n_rows = draw(st.integers(0, 5))
    lines = [",".join(header)]
    for _ in range(n_rows):
        width = len(header) if draw(st.booleans()) else draw(st.integers(0, 12))
        lines.append(",".join(draw(st.lists(cells, min_size=width, max_size=width))))
    if draw(st.booleans()):
        lines.insert(draw(st.integers(0, len(lines))), draw(st.sampled_from(
            ["# units: length=mm, angle=deg", "# units: length=m", "# units: angle=grad", "# c", "", "#units:"])))
    return draw(st.sampled_from(["\n", "\r\n"])).join(lines)


def _check_table(path, text=None):
    for columns, either in ((tuple("xyzabc"), ()), ((), (READING_COLUMNS, LENGTH_COLUMNS))):
        try:
            t = read_table(path, columns, either=either, text=text)
        except PkmcalError as exc:
            assert str(exc).startswith(str(path)) and "\n" not in str(exc)
            continue
        assert t.values.shape == (len(t.lines), len(t.columns)) and len(t) > 0
        assert np.all(np.isfinite(t.values))


@FUZZ
@given(csv_texts())
def test_random_csv_tables(text):
    _check_table("fuzz.csv", text)


@FUZZ
@given(st.binary(max_size=300))
def test_random_bytes_csv(tmp_path_factory, blob):
    path = tmp_path_factory.mktemp("t") / "fuzz.csv"
    path.write_bytes(blob)
    _check_table(path)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(csv_texts(), st.sampled_from(["ik", "fk"]))
def test_cli_on_random_tables(tmp_path_factory, text, command):
    d = tmp_path_factory.mktemp("cli")
    (d / "in.csv").write_text(text, encoding="utf-8")
    out = d / "out.csv"
    res = CliRunner().invoke(cli, [command, "stewart-prototype", str(d / "in.csv"), "-o", str(out)])
    assert res.exit_code in (0, 2), res.output
    if res.exit_code == 2:
        err = res.stderr.strip()
        assert err.startswith("pkmcal: error: ") and "\n" not in err and "Traceback" not in res.output
        assert not out.exists()
    else:
        assert out.exists()


@pytest.mark.parametrize("text", ["x,y,z,a,b,c\n1e308,1e308,1e308,1e308,1e308,1e308\n",
                                  "x,y,z,a,b,c\n0,0,0,0,0,0\n"])
def test_cli_extreme_but_valid_poses(tmp_path, text):
    (tmp_path / "in.csv").write_text(text)
    res = CliRunner().invoke(cli, ["ik", "stewart-prototype", str(tmp_path / "in.csv")])
    assert res.exit_code == 0, res.output
    assert res.stdout.splitlines()[-1].split(",")[-1] != "ok"
