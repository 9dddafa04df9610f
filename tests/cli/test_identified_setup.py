"""The identified sensor is part of the result (issue 11 item 2): ``pkmcal identify`` writes
it under ``setup:`` in CALIBRATED.yaml (setup-file form, degrees, 1σ, which covariance),
``--setup CALIBRATED.yaml`` reuses it bit for bit, and every machine-file kind keeps the
key on a load → save round trip, byte for byte.

Independent checks: the values in the file against the fit's own estimates (the engine
run in-process on the same inputs, and the ``--json`` table in degrees); the σ against
the fit's covariance; degree texts that :func:`~pkmcal.io._yaml.rad_to_deg_text` writes with
21 digits (no shorter text maps back exactly) read back to the same radians.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from helpers import assert_user_error
from test_json_units import uncovered
from test_verify_heldout import TRACKER_FREE, TRACKER_TRUE, ok, run

from pkmcal.identification.engine import identify
from pkmcal.io._yaml import rad_to_deg_text
from pkmcal.io.machine_file import load_machine, machine_from_text, machine_to_text
from pkmcal.io.measurements import load_measurements
from pkmcal.io.setup_file import identified_setup, load_setup
from pkmcal.mechanisms.library import builtin_machine, stewart_prototype
from pkmcal.sensors import FullPoseSensor

NOMINAL = stewart_prototype()


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    d = tmp_path_factory.mktemp("identified")
    (d / "setup.yaml").write_text(TRACKER_FREE)
    (d / "true.yaml").write_text(TRACKER_TRUE)
    r = np.random.default_rng(7)
    x = np.column_stack([r.uniform(-25, 25, 60), r.uniform(-25, 25, 60), r.uniform(-15, 15, 60) + NOMINAL.home_pose[2],
                         r.uniform(-4, 4, (60, 3))])
    (d / "poses.csv").write_text("x,y,z,a,b,c\n" + "".join(",".join(repr(float(v)) for v in row) + "\n" for row in x))
    ok(run("simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup", d / "true.yaml",
           "--poses", d / "poses.csv", "--seed", 5, "-o", d / "meas.csv"))
    ok(run("identify", "stewart-prototype", d / "meas.csv", "--setup", d / "setup.yaml", "-o", d / "cal.yaml"))
    setup = load_setup(d / "setup.yaml", NOMINAL)
    result = identify(NOMINAL, setup, load_measurements(d / "meas.csv", NOMINAL, setup))
    return d, result


def test_setup_block_in_degrees_with_std(campaign):
    d, result = campaign
    doc = yaml.safe_load((d / "cal.yaml").read_text())
    block = doc["setup"]
    assert block["sensor"] == "position" and block["free"] == list(result.sensor.default_free)
    est = dict(zip(result.names, result.estimate))
    for k in "xyz":
        assert block["target"][k] == pytest.approx(est[f"target.{k}"], abs=1e-12)
        assert block["world"][k] == pytest.approx(est[f"world.{k}"], abs=1e-12)
    for k in "abc":   # degrees in the file, radians in the fit
        assert block["world"][k] == pytest.approx(np.rad2deg(est[f"world.{k}"]), abs=1e-12)
        assert abs(block["world"][k]) > 1e-3
    std = dict(zip(result.free, result.std))
    assert set(block["std"]) == set(result.sensor.default_free)
    for n, v in block["std"].items():
        expected = np.rad2deg(std[n]) if n.endswith((".a", ".b", ".c")) else std[n]
        assert v == pytest.approx(expected, rel=1e-12), n
    assert block["covariance_kind"] == doc["calibration"]["std"]
    assert block["noise"] == {"distribution": "gaussian", "reading": 0.01, "actuator": 0.005}
    assert set(doc["calibration"]["before_registration"]) == set(result.sensor.default_free)


def test_setup_calibrated_file_reproduces_the_sensor_bit_for_bit(campaign):
    d, result = campaign
    cal = load_machine(d / "cal.yaml")
    setup = load_setup(d / "cal.yaml", cal)
    assert setup.sensor == result.sensor
    assert np.array_equal(setup.sensor.params, result.sensor.params)
    assert np.array_equal(setup.noise.reading_std, load_setup(d / "setup.yaml").noise.reading_std)
    # every command that takes --setup takes it: identifiability, simulate, identify again
    ok(run("identifiability", d / "cal.yaml", "--setup", d / "cal.yaml", "--poses", d / "poses.csv"))
    ok(run("simulate", d / "cal.yaml", "--real", "stewart-prototype-real", "--setup", d / "cal.yaml", "--poses",
           d / "poses.csv", "-o", d / "again.csv"))
    res = ok(run("identify", d / "cal.yaml", d / "meas.csv", "--setup", d / "cal.yaml", "-o", d / "cal2.yaml"))
    assert "wrote" in res.stdout
    assert yaml.safe_load((d / "cal2.yaml").read_text())["setup"]["sensor"] == "position"


def test_machine_file_round_trip_keeps_setup_exactly(campaign):
    d, _ = campaign
    text = (d / "cal.yaml").read_text()
    m = machine_from_text(text, "cal.yaml")
    assert machine_to_text(m) == text


def test_degree_texts_of_21_digits_round_trip(tmp_path):
    """Angles whose radians no shortest degree text reaches (``rad_to_deg_text`` then writes
    21 digits): written under setup:, loaded as a setup and as a machine, saved again."""
    r = np.random.default_rng(3)
    long_texts = []
    while len(long_texts) < 3:
        v = float(r.uniform(-0.2, 0.2))
        if len(rad_to_deg_text(v).lstrip("-").split("e")[0]) > 19:
            long_texts.append(v)
    angles = long_texts + [float(v) for v in r.uniform(-0.2, 0.2, 3)]
    theta = np.array([1.5, -2.25, 3.0, *angles[0:3], 0.5, 0.25, 20.0, *angles[3:6]])
    sensor = FullPoseSensor(world=theta[0:6], tool=theta[6:12], free=("world.a", "tool.c"))
    setup = load_setup("full-pose-paper1")
    block = identified_setup(setup, sensor, {"world.a": 1e-5, "tool.c": 2e-5}, "a-priori (noise model) covariance")
    import dataclasses

    machine = dataclasses.replace(NOMINAL, metadata={"setup": block})
    text = machine_to_text(machine)
    assert sum(len(t) > 20 for t in text.split()) >= 3   # the 21-digit texts are there
    path = tmp_path / "m.yaml"
    path.write_text(text)
    back = load_setup(path, NOMINAL).sensor
    assert np.array_equal(back.params, sensor.params)
    assert machine_to_text(load_machine(path)) == text
    assert load_setup(path).sensor.free == ("world.a", "tool.c")


@pytest.mark.parametrize("name", ["kossel-mini", "delta-picker", "planar-3dof-4act", "planar-2dof-3act"])
def test_every_machine_kind_keeps_setup(name, tmp_path):
    import dataclasses

    machine = builtin_machine(name)
    sensor_setup = load_setup("planar-tracker", machine) if name.startswith("planar") else load_setup("laser-tracker")
    block = identified_setup(sensor_setup, sensor_setup.sensor, {}, "a-priori")
    text = machine_to_text(dataclasses.replace(machine, metadata={"setup": block}))
    path = tmp_path / "m.yaml"
    path.write_text(text)
    back = load_machine(path)
    assert machine_to_text(back) == text
    assert load_setup(path, back).sensor == sensor_setup.sensor


def test_machine_file_without_setup_is_an_error_naming_it(tmp_path):
    path = tmp_path / "plain.yaml"
    path.write_text(machine_to_text(NOMINAL))
    assert_user_error(run("identifiability", "stewart-prototype", "--setup", path, "--poses", path),
                      "plain.yaml", "machine file without an identified setup")


def test_identify_json_states_units_and_the_identified_setup(campaign, tmp_path):
    d, result = campaign
    j = json.loads(ok(run("identify", "stewart-prototype", d / "meas.csv", "--setup", d / "setup.yaml", "-o",
                          tmp_path / "c.yaml", "--json")).stdout)
    assert uncovered(j) == []
    assert j["parameters"]["world.c"]["unit"] == "deg"
    assert j["parameters"]["world.c"]["estimate"] == pytest.approx(j["setup"]["world"]["c"], abs=1e-12)
    assert j["setup"]["std"]["world.c"] == pytest.approx(j["parameters"]["world.c"]["std"], rel=1e-12)
    assert set(j["before_registration"]["values"]) == set(result.sensor.default_free)
