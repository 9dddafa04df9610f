"""Setup YAML files: the documented examples, conversions, round trips and error messages."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.io.setup_file import BUILTIN_SETUPS, PROTOTYPE_INDICATORS, load_setup, save_setup, setup_to_yaml
from pkmcal.mechanisms.library import stewart_prototype
from pkmcal.sensors import FullPoseSensor, IndicatorSensor, MeasurementSetup, NoiseModel, PositionSensor


def _write(tmp_path, text, name="setup.yaml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_indicator_example(tmp_path):
    p = _write(tmp_path, """\
sensor: indicators
indicators: [[40, 0], [-20, 34.641], [-20, -34.641]]   # x, y in the base frame, mm
plane_offset: 10.0
noise: {reading: 0.01, actuator: 0.005}                 # std, mm
""")
    s = load_setup(p)
    assert isinstance(s.sensor, IndicatorSensor)
    np.testing.assert_array_equal(s.sensor.positions, [[40, 0], [-20, 34.641], [-20, -34.641]])
    assert s.sensor.plane_offset == 10.0
    np.testing.assert_array_equal(s.noise.reading_std, [0.01] * 3)
    assert float(s.noise.actuator_std) == 0.005 and s.noise.distribution == "gaussian"
    assert s.sensor.default_free == ()


def test_full_pose_uniform_half_widths_become_std(tmp_path):
    p = _write(tmp_path, """\
sensor: full-pose
world: {x: 100, c: 90}
tool: {z: 25, a: 1.5}
free: [world.x, world.c]
noise: {distribution: uniform, position: 0.025, orientation: [0.001, 0.002, 0.003], actuator: 0.01}
""")
    s = load_setup(p)
    np.testing.assert_allclose(s.noise.reading_std, np.array([0.025] * 3 + [0.001, 0.002, 0.003]) / math.sqrt(3))
    np.testing.assert_allclose(s.noise.actuator_std, 0.01 / math.sqrt(3))
    np.testing.assert_array_equal(s.sensor.world, [100, 0, 0, 0, 0, np.deg2rad(90.0)])
    np.testing.assert_array_equal(s.sensor.tool, [0, 0, 25, np.deg2rad(1.5), 0, 0])
    assert s.sensor.default_free == ("world.x", "world.c")


def test_orientation_in_degrees(tmp_path):
    p = _write(tmp_path, "sensor: full-pose\nnoise: {position: 0.01, orientation_deg: 0.05, actuator: 0.0}\n")
    np.testing.assert_allclose(load_setup(p).noise.reading_std[3:], np.deg2rad(0.05))


def test_position_setup_target_free_by_default(tmp_path):
    p = _write(tmp_path, "sensor: position\ntarget: {z: 30}\nnoise: {reading: [0.01, 0.02, 0.03], actuator: 0.005}\n")
    s = load_setup(p)
    assert isinstance(s.sensor, PositionSensor)
    np.testing.assert_array_equal(s.sensor.target, [0, 0, 30])
    assert s.sensor.default_free == ("target.x", "target.y", "target.z")
    np.testing.assert_array_equal(s.noise.reading_std, [0.01, 0.02, 0.03])


def test_builtin_setups():
    ind = load_setup("indicators-prototype")
    np.testing.assert_array_equal(ind.sensor.positions, PROTOTYPE_INDICATORS)
    radius = np.linalg.norm(PROTOTYPE_INDICATORS, axis=1)
    np.testing.assert_allclose(radius, 40.0)
    np.testing.assert_allclose(np.rad2deg(np.arctan2(PROTOTYPE_INDICATORS[:, 1], PROTOTYPE_INDICATORS[:, 0])),
                               [0, 120, -120], atol=1e-12)
    assert radius.max() < stewart_prototype().platform_radius
    p1 = load_setup("full-pose-paper1")
    assert p1.noise.distribution == "uniform"
    np.testing.assert_allclose(p1.noise.reading_std * math.sqrt(3), [0.025] * 3 + [0.001] * 3)
    assert isinstance(load_setup("laser-tracker").sensor, PositionSensor)
    assert set(BUILTIN_SETUPS) == {"indicators-prototype", "full-pose-paper1", "laser-tracker", "planar-tracker",
                                   "planar-tracker-rotary", "planar-tracker-linear", "z-probe-klipper",
                                   "printed-distance-klipper"}


@settings(max_examples=25, deadline=None)
@given(
    kind=st.sampled_from(["full-pose", "position", "indicators"]),
    vals=st.lists(st.floats(-200, 200, allow_nan=False), min_size=12, max_size=12),
    std=st.lists(st.floats(0, 1, allow_nan=False), min_size=6, max_size=6),
    uniform=st.booleans(),
)
def test_save_load_round_trip(tmp_path_factory, kind, vals, std, uniform):
    v = np.array(vals)
    ang = np.deg2rad(v[3:6] / 2)
    if kind == "full-pose":
        sensor = FullPoseSensor(world=np.r_[v[:3], ang], tool=np.r_[v[6:9], ang[::-1]], free=("tool.z",))
        rs = np.array(std)
    elif kind == "position":
        sensor = PositionSensor(target=v[:3], world=np.r_[v[6:9], ang])
        rs = np.array(std[:3])
    else:
        sensor = IndicatorSensor(positions=v[:8].reshape(4, 2), plane_offset=v[8], zero=v[9:12].tolist() + [1.0],
                                 free=("zero2",))
        rs = np.array(std[:4])
    setup = MeasurementSetup(sensor, NoiseModel(rs, np.array(std[5]), "uniform" if uniform else "gaussian"))
    path = tmp_path_factory.mktemp("rt") / "s.yaml"
    save_setup(setup, path)
    back = load_setup(path)
    assert back.sensor.kind == kind and back.sensor.default_free == sensor.default_free
    np.testing.assert_array_equal(back.sensor.params, sensor.params)  # degrees written exactly
    # angle noise in degrees in the file: rad → deg → rad, relative error ≤ 2ε (four roundings
    # of u = ε/2: two products, two rounded constants); 1e-15 ≈ 4.5ε
    np.testing.assert_allclose(back.noise.reading_std, rs, rtol=1e-15, atol=0)
    np.testing.assert_allclose(back.noise.actuator_std, std[5], rtol=1e-15, atol=0)
    assert back.noise.distribution == setup.noise.distribution
    assert setup_to_yaml(back) == path.read_text()  # deterministic


@pytest.mark.parametrize(
    "text, pattern",
    [
        ("sensor: indicators\nplane_offset: 1\nnoise: {reading: 0.01, actuator: 0.01}\n",
         r"line 1: key 'indicators': is missing; give the indicator positions"),
        ("sensor: laser\nnoise: {actuator: 0.01}\n", r"line 1: key 'sensor': must be one of full-pose, position, indicators"),
        ("noise: {actuator: 0.01}\n", r"key 'sensor': is missing"),
        ("sensor: position\nnoise:\n  reading: 0.01\n  actuator: 0.01\n  bogus: 2\n",
         r"line 5: key 'noise.bogus': is not a setup key here.*allowed: distribution, reading"),
        ("sensor: position\nnoise: {reading: 0.01}\n", r"key 'noise.actuator': is missing"),
        ("sensor: full-pose\nnoise: {position: -1, orientation: 0.001, actuator: 0.01}\n",
         r"line 2: key 'noise.position'.*non-negative"),
        ("sensor: full-pose\nnoise: {position: 0.01, actuator: 0.01}\n", r"exactly one of orientation"),
        ("sensor: indicators\nindicators: [[0, 0], [1, 0]]\nplane_offset: 0\nnoise: {reading: 0.01, actuator: 0.01}\n",
         r"line 2: key 'indicators': needs at least 3"),
        ("sensor: indicators\nindicators: [[0, 0], [1, 0], [0, 1]]\nplane_offset: 0\n"
         "noise: {reading: [0.01, 0.02], actuator: 0.01}\n", r"key 'noise.reading': give one value or 3 values"),
        ("sensor: indicators\nindicators: [[0, 0], [1, 0], [0, 1]]\nplane_offset: 0\nfree: [zero4]\n"
         "noise: {reading: 0.01, actuator: 0.01}\n", r"line 4: key 'free':.*no parameter 'zero4'"),
        ("sensor: indicators\nindicators: [[0, 0], [1, 0], [0, 1]]\nplane_offset: 0\ntool: {x: 1}\n"
         "noise: {reading: 0.01, actuator: 0.01}\n", r"line 4: key 'tool': does not apply to sensor 'indicators'"),
        ("sensor: full-pose\nworld: {x: abc}\nnoise: {position: 0.01, orientation: 0.001, actuator: 0.01}\n",
         r"line 2: key 'world.x'"),
        ("sensor: [full-pose\n", r"not valid YAML"),
        ("- 1\n- 2\n", r"a setup file is a YAML mapping"),
    ],
)
def test_error_messages_name_file_line_and_key(tmp_path, text, pattern):
    p = _write(tmp_path, text)
    with pytest.raises(InputFileError, match=pattern) as err:
        load_setup(p)
    assert str(p) in str(err.value)


def test_unknown_name_lists_builtins():
    with pytest.raises(PkmcalError, match="not a built-in setup.*indicators-prototype"):
        load_setup("no-such-setup.yaml")


# -- planar-tool setups (paper 3) ----------------------------------------------------------


def test_planar_tool_setup_round_trip_and_binding(tmp_path):
    from pkmcal.io.setup_file import bind_setup
    from pkmcal.mechanisms.library import builtin_machine
    from pkmcal.sensors import PlanarToolSensor

    p = tmp_path / "s.yaml"
    p.write_text("sensor: planar-tool\ntarget: {x: 1.5, y: -2}\nworld: {x: 10, y: 5, c: 30}\n"
                 "free: [target.x, target.y, world.x, world.y, world.c]\n"
                 "noise: {reading: 0.01, actuator: [1.0e-5, 2.0e-5, 3.0e-5]}\n"
                 "simulation: {stiffness: [5.0e7, 4.0e7, 3.0e7], load: [0, -30]}\n")
    m2 = builtin_machine("planar-2dof-3act")
    s = load_setup(p, m2)
    assert isinstance(s.sensor, PlanarToolSensor) and s.sensor.n_pose == 2
    np.testing.assert_array_equal(s.sensor.params, [1.5, -2.0, 10.0, 5.0, np.deg2rad(30.0)])
    np.testing.assert_array_equal(s.simulation.stiffness_for(m2), [5e7, 4e7, 3e7])
    np.testing.assert_array_equal(s.simulation.load, [0.0, -30.0])
    q = tmp_path / "s2.yaml"
    save_setup(s, q)
    back = load_setup(q, m2)
    assert np.array_equal(back.sensor.params, s.sensor.params) and back.sensor.free == s.sensor.free
    assert np.array_equal(back.noise.actuator_std, s.noise.actuator_std)
    assert np.array_equal(back.simulation.stiffness, s.simulation.stiffness)
    assert np.array_equal(back.simulation.load, s.simulation.load)
    # bound to a 3-dof machine the sensor takes 3 pose coordinates; the 3 stiffnesses do not fit 4 actuators
    with pytest.raises(PkmcalError, match="4 actuators"):
        load_setup(p, builtin_machine("planar-3dof-4act"))
    with pytest.raises(PkmcalError, match="cannot measure"):
        bind_setup(s, stewart_prototype())
    with pytest.raises(PkmcalError, match="cannot measure"):
        load_setup("laser-tracker", m2)


def test_planar_builtin_setups_match_the_benchmark():
    from pkmcal.mechanisms.library import builtin_machine

    rot = load_setup("planar-tracker", builtin_machine("planar-2dof-3act"))
    lin = load_setup("planar-tracker", builtin_machine("planar-3dof-4act"))
    assert rot.sensor.n_pose == 2 and lin.sensor.n_pose == 3
    np.testing.assert_array_equal(rot.noise.reading_std, [0.010, 0.010])
    assert float(rot.noise.actuator_std) == 1e-5 and float(lin.noise.actuator_std) == 1e-3
    assert float(rot.simulation.stiffness) == 5e7 and float(lin.simulation.stiffness) == 2e4
    np.testing.assert_array_equal(lin.simulation.load, [0.0, -30.0])
    with pytest.raises(PkmcalError, match="planar-tracker-rotary"):
        load_setup("planar-tracker")
    assert load_setup("planar-tracker-linear").sensor.kind == "planar-tool"


@pytest.mark.parametrize("text, key", [
    ("sensor: planar-tool\ntarget: {x: 0, y: 0, z: 1}\nnoise: {reading: 0.01, actuator: 0}\n", "target.z"),
    ("sensor: planar-tool\nworld: {a: 1}\nnoise: {reading: 0.01, actuator: 0}\n", "world.a"),
    ("sensor: planar-tool\nnoise: {reading: 0.01, actuator: 0}\nsimulation: {stiffness: -1}\n", "simulation.stiffness"),
    ("sensor: planar-tool\nnoise: {reading: 0.01, actuator: 0}\nsimulation: {stiffness: 1, load: [1, 2, 3]}\n",
     "simulation.load"),
    ("sensor: planar-tool\nnoise: {reading: 0.01, actuator: 0}\nsimulation: {stifness: 1}\n", "simulation.stifness"),
    ("sensor: position\nnoise: {reading: 0.01, actuator: 0}\nsimulation: {stiffness: 1}\n", "simulation"),
    ("sensor: planar-tool\nnoise: {actuator: 0}\n", "noise.reading"),
])
def test_planar_tool_setup_errors(tmp_path, text, key):
    p = tmp_path / "bad.yaml"
    p.write_text(text)
    with pytest.raises(InputFileError) as exc:
        load_setup(p)
    assert f"key '{key}'" in str(exc.value) and "bad.yaml" in str(exc.value) and "line" in str(exc.value)


def test_saved_sensor_parameters_are_in_file_units_by_the_declared_angle_flags(tmp_path):
    """Every θ value a setup file holds is the sensor's parameter in file units: degrees for
    the parameters its ``param_is_angle`` declares (transform a, b, c; planar world.c), mm
    for the rest; reading the file gives back the same radians."""
    import yaml

    from pkmcal.sensors import PlanarToolSensor

    rad = np.deg2rad([0.3, -1.1, 2.5, 7.0, -0.2, 45.0])
    sensors = [
        FullPoseSensor(world=np.r_[1.0, 2.0, 3.0, rad[:3]], tool=np.r_[4.0, 5.0, 6.0, rad[3:]]),
        PositionSensor(target=[1.0, 2.0, 30.0], world=np.r_[-1.0, 0.5, 2.0, rad[:3]]),
        PlanarToolSensor(n_pose=3, target=[0.5, -0.25], world=[10.0, 5.0, rad[5]]),
    ]
    for k, sensor in enumerate(sensors):
        setup = MeasurementSetup(sensor, NoiseModel(np.full(sensor.n_readings, 0.01), np.array(0.005)))
        doc = yaml.safe_load(setup_to_yaml(setup))
        for name, value, is_angle in zip(sensor.param_names, sensor.params, sensor.param_is_angle):
            group, key = name.split(".")
            assert doc[group][key] == pytest.approx(np.rad2deg(value) if is_angle else value, rel=1e-15), name
        path = tmp_path / f"s{k}.yaml"
        save_setup(setup, path)
        np.testing.assert_array_equal(load_setup(path).sensor.params, sensor.params)
