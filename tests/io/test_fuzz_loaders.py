"""Fuzzing the loaders: whatever the bytes, a machine file or CSV table either loads or raises
a PkmcalError with a one-line message (the CLI: exit code 2), never another exception."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from helpers import (
    PROTOTYPE_LEGS_YAML,
    assert_ok_or_user_error,
    csv_texts,
    dump_yaml,
    fuzz_file,
    fuzz_settings,
    keys,
    mutate,
    structures,
)
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pkmcal.cli.main import cli
from pkmcal.errors import PkmcalError
from pkmcal.io import machine_from_text, read_machine_file, read_table
from pkmcal.io.tables import LENGTH_COLUMNS, READING_COLUMNS
from pkmcal.mechanisms.base import Mechanism

FUZZ = fuzz_settings(300)

VALID = yaml.safe_load("name: fuzz\nlegs:\n" + PROTOTYPE_LEGS_YAML + """\
limits: {u_joint_tilt: 45, s_joint_tilt: 29, leg_diameter: 36.1, singularity_margin: 0.01}
home: {x: 0, y: 0, z: 315, a: 0, b: 0, c: 0}
workspace: {x: [-10, 10], y: [-10, 10], z: [300, 330], a: [-5, 5], b: [-5, 5], c: [-30, 30]}
uncertainty: {parameters: [b1.x, L0_2], std: {b1.x: 0.02, L0_2: 0.05}, correlation: [[1, 0.5], [0.5, 1]]}
calibration: {method: ik-residual, n_poses: 30}
""")


def _check_machine_text(text: str) -> None:
    try:
        m = machine_from_text(text, "fuzz.yaml")
    except PkmcalError as exc:
        msg = str(exc)
        assert msg.startswith("fuzz.yaml") and "\n" not in msg
        return
    assert isinstance(m, Mechanism)


@st.composite
def mutated_machines(draw):
    return mutate(draw, copy.deepcopy(VALID), structures, keys)


def test_valid_fuzz_base_loads():
    m = machine_from_text(yaml.safe_dump(VALID), "fuzz.yaml")
    assert m.name == "fuzz"


@FUZZ
@given(structures)
def test_random_yaml_structures(data):
    _check_machine_text(dump_yaml(data))


@FUZZ
@given(mutated_machines())
def test_mutated_machine_files(data):
    _check_machine_text(dump_yaml(data))


@FUZZ
@given(st.text(max_size=200))
def test_random_text_machine(text):
    _check_machine_text(text)


@FUZZ
@given(st.binary(max_size=200))
def test_random_bytes_machine(tmp_path_factory, blob):
    path = fuzz_file(tmp_path_factory, "fuzz.yaml", blob)
    try:
        read_machine_file(path)
    except PkmcalError as exc:
        assert str(exc).startswith(str(path)) and "\n" not in str(exc)


# -- CSV -----------------------------------------------------------------------------------------

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
    path = fuzz_file(tmp_path_factory, "fuzz.csv", blob)
    _check_table(path)


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(csv_texts(), st.sampled_from(["ik", "fk"]))
def test_cli_on_random_tables(tmp_path_factory, text, command):
    d = tmp_path_factory.mktemp("cli")
    (d / "in.csv").write_text(text, encoding="utf-8")
    out = d / "out.csv"
    poses = ["--poses"] if command == "ik" else []          # fk reads its actuator file as the argument
    res = CliRunner().invoke(cli, [command, "stewart-prototype", *poses, str(d / "in.csv"), "-o", str(out)])
    assert_ok_or_user_error(res, out)
    if res.exit_code == 0:
        assert out.exists()


@pytest.mark.parametrize("text", ["x,y,z,a,b,c\n1e308,1e308,1e308,1e308,1e308,1e308\n",
                                  "x,y,z,a,b,c\n0,0,0,0,0,0\n"])
def test_cli_extreme_but_valid_poses(tmp_path, text):
    (tmp_path / "in.csv").write_text(text)
    res = CliRunner().invoke(cli, ["ik", "stewart-prototype", "--poses", str(tmp_path / "in.csv")])
    assert res.exit_code == 0, res.output
    assert res.stdout.splitlines()[-1].split(",")[-1] != "ok"
