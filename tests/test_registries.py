"""The machine-kind and sensor-kind registries (issue 12 item 2; docs/architecture.md).

* every registered machine kind and sensor kind round-trips through its file exactly (the
  object, and the text written again byte for byte), identified machines included;
* an unknown kind is an error naming the known kinds and the line;
* a kind registered in a test (a toy machine and a toy sensor) is read and written by the
  unchanged drivers (``machine_from_text``/``machine_to_text``, ``load_setup``/``save_setup``);
* a family in the generic ``parameters:`` layout needs only its registration line.
"""

from __future__ import annotations

import dataclasses
import re
from types import MappingProxyType

import numpy as np
import pytest

import pkmcal.io.machine_file as machine_file
import pkmcal.io.setup_file as setup_file
from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.io.machine_file import (
    load_machine,
    machine_from_text,
    machine_kinds,
    machine_to_text,
    register_machine_kind,
    save_machine,
)
from pkmcal.io.setup_file import (
    BUILTIN_SETUPS,
    SensorFileKind,
    identified_setup,
    load_setup,
    register_sensor_kind,
    save_setup,
    sensor_kinds,
    setup_to_yaml,
)
from pkmcal.io.parameter_machine_file import register_parameter_kind
from pkmcal.mechanisms import BUILTIN_MACHINES, Hexapod, builtin_machine
from pkmcal.mechanisms.rss_hexapod import RSSHexapod
from pkmcal.sensors import PositionSensor

MACHINES = {name: builtin_machine(name) for name in BUILTIN_MACHINES}
MACHINES["symmetric:platform_separation=0"] = builtin_machine("symmetric:platform_separation=0")


def _identified(m, seed: int = 0):
    """``m`` as ``pkmcal identify`` leaves it: moved parameters, a covariance with a held
    (zero) row, calibration metadata and an identified setup with sensor σ."""
    rng = np.random.default_rng(seed)
    p = len(m.param_names)
    a = rng.normal(size=(p, p)) * 1e-3
    cov = a @ a.T
    cov[0, :] = cov[:, 0] = 0.0
    cal = m.with_params(m.params + rng.normal(size=p) * 1e-4, name=f"{m.name}-cal", covariance=cov)
    setup = load_setup("planar-tracker" if "planar" in m.abilities else "indicators-prototype", m)
    sensor = setup.sensor.with_params(setup.sensor.params + 1e-3)
    ident = identified_setup(setup, sensor, {n: 0.01 for n in sensor.param_names}, "fit")
    return dataclasses.replace(cal, metadata={"calibration": {"method": "fk-residual", "rms": 0.01},
                                              "setup": ident, "operator": "test"})


def _same_machine(a, b, metadata: bool = True) -> None:
    assert a == b
    assert a.kind == b.kind and type(a) is type(b)
    assert np.array_equal(a.params, b.params)   # bit for bit
    assert (a.covariance is None) == (b.covariance is None)
    if a.covariance is not None:
        assert np.array_equal(a.covariance, b.covariance)
    if metadata:
        assert a.metadata == b.metadata


def test_every_builtin_machine_kind_is_registered():
    kinds = {m.kind for m in MACHINES.values()}
    assert kinds == {"6-UPS", "6-RSS", "6-PUS", "linear-delta", "rotary-delta", "planar-2dof-3act",
                     "planar-3dof-4act"}
    assert kinds - {"6-UPS"} <= set(machine_kinds())
    assert {"hexapod", "6-UPS"} <= set(machine_kinds())


@pytest.mark.parametrize("name", sorted(MACHINES))
@pytest.mark.parametrize("identified", [False, True], ids=["nominal", "identified"])
def test_every_machine_kind_round_trips_exactly(name, identified, tmp_path):
    m = MACHINES[name]
    m = _identified(m) if identified else m
    text = machine_to_text(m)
    back = machine_from_text(text, "m.yaml")
    # an identified setup holds degree texts in memory, numbers with their text once read:
    # the same file (compared below), not equal mappings
    _same_machine(m, back, metadata=not identified)
    assert set(back.metadata) == set(m.metadata)
    assert machine_to_text(back) == text
    path = tmp_path / "m.yaml"
    save_machine(back, path)       # the checked write: loads back equal, metadata included (an
    assert path.read_text(encoding="utf-8") == text   # identified 6-RSS/6-PUS could not be saved before)
    _same_machine(back, load_machine(path))


def test_the_hexapod_is_written_as_hexapod_and_read_under_both_spellings():
    m = MACHINES["stewart-prototype"]
    text = machine_to_text(m)
    assert text.startswith("# pkmcal machine file (kind: hexapod)") and "\nkind: hexapod\n" in text
    other = machine_from_text(text.replace("\nkind: hexapod\n", "\nkind: 6-UPS\n"))
    none = machine_from_text(text.replace("\nkind: hexapod\n", "\n"))
    _same_machine(m, other)
    _same_machine(m, none)


SETUP_CASES = {
    "indicators": ("indicators-prototype", "stewart-prototype"),
    "full-pose": ("full-pose-paper1", "stewart-prototype"),
    "position": ("laser-tracker", "stewart-prototype"),
    "z-probe": ("z-probe-klipper", "kossel-mini"),
    "printed-distance": ("printed-distance-klipper", "kossel-mini"),
    "planar-tool": ("planar-tracker", "planar-3dof-4act"),
    "distance": ("examples/setup-ballbar.yaml", "stewart-prototype"),
}


def test_every_sensor_kind_has_a_round_trip_case():
    assert set(SETUP_CASES) == set(sensor_kinds())


@pytest.mark.parametrize("kind", sorted(SETUP_CASES))
@pytest.mark.parametrize("moved", [False, True], ids=["as-built", "moved-parameters"])
def test_every_sensor_kind_round_trips_exactly(kind, moved, tmp_path):
    import pathlib

    spec, machine = SETUP_CASES[kind]
    if spec.endswith(".yaml"):
        spec = str(pathlib.Path(__file__).resolve().parents[1] / spec)
    reader = MACHINES[machine]
    if kind == "printed-distance":    # its readings couple two poses: the machine read as pairs
        from pkmcal.mechanisms.pose_pairs import PosePairs

        reader = PosePairs(reader)
    setup = load_setup(spec, reader)
    assert setup.sensor.kind == kind
    if moved:   # every sensor parameter off its default, angles included (degree texts exact)
        theta = setup.sensor.params + np.linspace(1e-3, 2e-3, len(setup.sensor.params))
        setup = dataclasses.replace(setup, sensor=setup.sensor.with_params(theta))
    text = setup_to_yaml(setup)
    path = tmp_path / "setup.yaml"
    save_setup(setup, path)
    back = load_setup(path, reader)
    assert back.sensor.kind == kind and type(back.sensor) is type(setup.sensor)
    assert np.array_equal(back.sensor.params, setup.sensor.params)
    assert back.sensor.free == setup.sensor.free
    assert np.array_equal(back.noise.reading_std, setup.noise.reading_std)
    assert np.array_equal(back.noise.actuator_std, setup.noise.actuator_std)
    assert setup_to_yaml(back) == text


def test_an_unknown_machine_kind_names_the_known_kinds_and_the_line():
    with pytest.raises(InputFileError) as err:
        machine_from_text("name: x\ndescription: y\nkind: pentapod\n", "m.yaml")
    text = str(err.value)
    assert "line 3" in text and "'pentapod' is not a known machine kind" in text
    assert text.endswith("known kinds: " + ", ".join(machine_kinds()))


def test_an_unknown_sensor_kind_names_the_known_kinds_and_the_line(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text("description: x\nsensor: sonar\nnoise: {reading: 0.01, actuator: 0.01}\n", encoding="utf-8")
    with pytest.raises(InputFileError) as err:
        load_setup(path)
    text = str(err.value)
    assert "line 2" in text and "key 'sensor'" in text
    assert text.endswith("must be one of " + ", ".join(sensor_kinds()))


def test_a_setup_without_a_sensor_names_every_kind(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text("noise: {reading: 0.01, actuator: 0.01}\n", encoding="utf-8")
    with pytest.raises(InputFileError, match=re.escape("key 'sensor': is missing; say which sensor: one of "
                                                       + ", ".join(sensor_kinds()))):
        load_setup(path)
    path.write_text("- sensor: indicators\n", encoding="utf-8")
    with pytest.raises(InputFileError, match=re.escape("sensor: " + "|".join(sensor_kinds()))):
        load_setup(path)


def test_a_machine_without_a_file_kind_is_an_error_naming_its_kind():
    @dataclasses.dataclass(frozen=True, eq=False)
    class Unfiled(Hexapod):
        kind = "6-UPS-unfiled"

    m = MACHINES["stewart-prototype"]
    odd = Unfiled(name="odd", base=m.base, platform=m.platform, offset=m.offset, stroke=m.stroke)
    with pytest.raises(PkmcalError, match=r"no machine file format for its kind '6-UPS-unfiled' \(kinds with one: "
                                          r"6-UPS, "):
        machine_to_text(odd)


def test_an_unknown_key_is_hinted_with_the_kinds_own_keys():
    text = machine_to_text(MACHINES["hexaslide"]) + "stroke_min: 1\n"
    with pytest.raises(InputFileError, match=r"unknown key 'stroke_min'; allowed keys here: kind, name, "
                                             r"description, legs, limits, home, workspace, uncertainty, "
                                             r"calibration, metadata, setup$"):
        machine_from_text(text)
    text = machine_to_text(MACHINES["hexaslide"]).replace("branch: -1", "branch: 2", 1)
    with pytest.raises(InputFileError, match=r"legs\[0\]\.branch \(leg 1\): expected -1 or 1, got 2$"):
        machine_from_text(text)


# -- a kind registered in a test: the drivers are not touched -----------------------------


@dataclasses.dataclass(frozen=True, eq=False)
class ToyHexapod(Hexapod):
    """A made-up family: a hexapod described in its file by one number (the legs' offset)."""

    kind = "toy-ups"


def _toy_from_file(source, data: dict, lines: dict) -> ToyHexapod:
    if set(data) != {"kind", "name", "offset"} or not isinstance(data["offset"], float):
        raise InputFileError(source, "a toy file has kind, name and offset (a number)", line=lines.get(()))
    m = MACHINES["stewart-prototype"]
    return ToyHexapod(name=data["name"], base=m.base, platform=m.platform, offset=np.full(6, data["offset"]),
                      stroke=m.stroke)


def _toy_to_file(m: ToyHexapod) -> dict:
    return {"kind": "toy-ups", "name": m.name, "offset": float(m.offset[0])}


class ToyTracker(PositionSensor):
    """A made-up sensor kind: a position tracker whose file gives only its target."""

    kind = "toy-tracker"


def _toy_sensor_from_file(ctx):
    t = ctx.spec.target
    sensor = ToyTracker(target=None if t is None else [t.x, t.y, t.z], free=ctx.free)
    return sensor, ctx.reading_std(3, "the toy's noise (mm)")


def _toy_sensor_to_file(s) -> dict:
    return {"target": {k: float(v) for k, v in zip("xyz", s.target)}}


@pytest.fixture
def own_registries(monkeypatch):
    """The registries as copies, so that a test's registrations end with the test."""
    monkeypatch.setattr(machine_file, "_KINDS", dict(machine_file._KINDS))
    monkeypatch.setattr(machine_file, "_WRITERS", dict(machine_file._WRITERS))
    monkeypatch.setattr(setup_file, "_SENSOR_KINDS", dict(setup_file._SENSOR_KINDS))


def test_a_registered_machine_kind_is_loaded_and_saved_by_the_drivers(own_registries, tmp_path):
    assert "toy-ups" not in machine_kinds()
    register_machine_kind("toy-ups", _toy_from_file, ToyHexapod, _toy_to_file, aliases=("toy",))
    assert machine_kinds()[-2:] == ("toy-ups", "toy")
    m = _toy_from_file("x", {"kind": "toy-ups", "name": "toy", "offset": 300.5}, {})
    path = tmp_path / "toy.yaml"
    save_machine(m, path)
    assert path.read_text(encoding="utf-8") == ("# pkmcal machine file (kind: toy-ups); lengths in mm, angles in "
                                                "degrees\nkind: toy-ups\nname: toy\noffset: 300.5\n")
    back = load_machine(path)
    assert type(back) is ToyHexapod and back == m and np.array_equal(back.params, m.params)
    assert type(machine_from_text("kind: toy\nname: toy\noffset: 300.5\n")) is ToyHexapod
    with pytest.raises(InputFileError, match="known kinds: .*, toy-ups, toy$"):
        machine_from_text("kind: toy-upss\n")
    # the built-in kinds are unaffected
    _same_machine(MACHINES["stewart-prototype"], machine_from_text(machine_to_text(MACHINES["stewart-prototype"])))


def test_a_registered_sensor_kind_is_loaded_and_saved_by_the_drivers(own_registries, tmp_path):
    assert "toy-tracker" not in sensor_kinds()
    register_sensor_kind(SensorFileKind("toy-tracker", ("target",), _toy_sensor_from_file, _toy_sensor_to_file))
    path = tmp_path / "toy.yaml"
    path.write_text("sensor: toy-tracker\ntarget: {x: 1.5, y: 0, z: 30}\nnoise: {reading: 0.02, actuator: 0.01}\n",
                    encoding="utf-8")
    setup = load_setup(path)
    assert type(setup.sensor) is ToyTracker and np.array_equal(setup.sensor.target, [1.5, 0.0, 30.0])
    assert np.array_equal(setup.noise.reading_std, [0.02] * 3)
    out = tmp_path / "again.yaml"
    save_setup(setup, out)
    assert "sensor: toy-tracker\n" in out.read_text(encoding="utf-8")
    again = load_setup(out)
    assert np.array_equal(again.sensor.params, setup.sensor.params) and type(again.sensor) is ToyTracker
    # its keys are checked like a built-in's: a key of another kind is refused, naming the kind's keys
    path.write_text("sensor: toy-tracker\ntarget: {x: 1}\nworld: {x: 1}\nnoise: {reading: 0.02, actuator: 0.01}\n",
                    encoding="utf-8")
    with pytest.raises(InputFileError, match=re.escape("key 'world': does not apply to sensor 'toy-tracker' "
                                                       "(its keys: target)")):
        load_setup(path)


def test_a_sensor_kind_with_a_key_the_schema_lacks_is_refused(own_registries):
    with pytest.raises(ValueError, match="sonar_beam not setup keys"):
        register_sensor_kind(SensorFileKind("sonar", ("sonar_beam",), _toy_sensor_from_file, _toy_sensor_to_file))
    assert "sonar" not in sensor_kinds()


def test_builtin_setups_cover_every_kind_they_name():
    """Each built-in setup's sensor is of a registered kind (a new built-in needs its kind)."""
    for name in BUILTIN_SETUPS:
        for machine in ("stewart-prototype", "kossel-mini", "planar-3dof-4act"):
            try:
                setup = load_setup(name, MACHINES[machine])
            except PkmcalError:
                continue
            assert setup.sensor.kind in sensor_kinds()
            break


# -- a family in the generic layout: one registration line, no file schema of its own ----------


@dataclasses.dataclass(frozen=True, eq=False)
class ToyRSS(RSSHexapod):
    """A made-up family (a 6-RSS under another kind) filed in the generic ``parameters:`` layout."""

    kind = "toy-rss"
    limit_keywords = MappingProxyType({"motor_range": True, "max_joint_angle": True})


def test_a_family_in_the_generic_layout_needs_only_its_registration(own_registries, tmp_path):
    register_parameter_kind("toy-rss", f"{__name__}:ToyRSS")   # what a line of PARAMETER_FILE_KINDS does
    real = _identified(MACHINES["servo-stewart"], seed=3)
    m = ToyRSS(name="toy", rho=real.rho, motor_range=(np.deg2rad(-55.5), np.deg2rad(61.25)),
               max_joint_angle=np.deg2rad(58.0), workspace=real.workspace_box(), home=real.home,
               covariance=real.covariance, description="a toy", metadata=real.metadata)
    text = machine_to_text(m)
    assert "\nkind: toy-rss\n" in text and "\nparameters:\n  s1.x: " in text
    assert "\nlimits:\n  motor_range: [-55.5, 61.25]\n  max_joint_angle: 58.0\n" in text   # degrees
    assert "  beta_1: " in text and "  a: [" in text
    back = machine_from_text(text, "toy.yaml")
    _same_machine(m, back, metadata=False)
    assert back.motor_range == m.motor_range and back.max_joint_angle == m.max_joint_angle
    assert np.array_equal(back.workspace, m.workspace) and np.array_equal(back.home, m.home)
    assert machine_to_text(back) == text
    path = tmp_path / "toy.yaml"
    save_machine(back, path)
    _same_machine(back, load_machine(path))
    # the errors name the parameter, with the line
    bad = text.replace("  beta_1: ", "  betta_1: ", 1)
    with pytest.raises(InputFileError, match=r"line \d+: parameters.betta_1: unknown parameter \(did you mean "
                                             r"'beta_1'\?\)"):
        machine_from_text(bad)
    bad = re.sub(r"\n  beta_1: [^\n]*", "", text, count=1)
    with pytest.raises(InputFileError, match=r"parameters: missing beta_1; give every parameter"):
        machine_from_text(bad)
    with pytest.raises(InputFileError, match=r"limits.motor_rang: unknown limit \(did you mean 'motor_range'\?\)"):
        machine_from_text(text.replace("  motor_range:", "  motor_rang:"))


# -- the declarations the CLI, report and export read instead of probing ----------------------


@pytest.mark.parametrize("name", sorted(MACHINES))
def test_declared_description_metadata_workspace(name):
    m = MACHINES[name]
    assert isinstance(m.description, str) and dict(m.metadata) == {}
    assert m.workspace is None or np.array_equal(m.workspace, m.workspace_box())
    if "stroke" in m.abilities:   # exported as actuator_stroke: the readings' [min, max]
        rng = m.reading_range()
        assert rng.shape == (m.n_actuators, 2) and np.all(rng[:, 0] <= rng[:, 1])
        q = m.ik(m.home_pose[None])[0]
        assert np.all((rng[:, 0] <= q) & (q <= rng[:, 1]))   # home is within the stroke


@pytest.mark.parametrize("name", sorted(n for n, m in MACHINES.items() if m.reach() is not None))
def test_reach_bounds_every_reachable_pose(name):
    """``reach()`` bounds ‖p‖ of every pose the limits admit: poses sampled in three times the
    planning box about home, and along each translation axis out to 1.2 × reach."""
    m = MACHINES[name]
    r = m.reach()
    rng = np.random.default_rng(7)
    home = m.home_pose
    box = m.workspace_box()
    lo, hi = home + 3.0 * (box[:, 0] - home), home + 3.0 * (box[:, 1] - home)
    poses = [rng.uniform(lo, hi, size=(20_000, m.n_dof))]
    for k in range(3):
        line = np.repeat(home[None], 2001, axis=0)
        line[:, k] = np.linspace(-1.2 * r, 1.2 * r, 2001)
        poses.append(line)
    poses = np.concatenate(poses)
    with np.errstate(all="ignore"):
        ok = m.check_limits(poses).ok
    assert ok.sum() > 50
    assert np.max(np.linalg.norm(poses[ok, :3], axis=1)) <= r
    assert np.linalg.norm(home[:3]) <= r
