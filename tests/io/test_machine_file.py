"""Machine files: the minimal form, exact save→load round trips, and every error path."""

from __future__ import annotations

import math
import os
import stat
import warnings
from dataclasses import replace

import numpy as np
import pytest
import yaml
from helpers import PROTOTYPE_LEGS_YAML
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.io import load_machine, machine_from_text, machine_to_text, read_machine_file, save_machine
from pkmcal.io._yaml import TextFloat, deg_to_rad, parse_yaml, rad_to_deg_text
from pkmcal.mechanisms.hexapod import HEXAPOD_PARAM_NAMES, Hexapod, HexapodLimits
from pkmcal.mechanisms.library import PROTOTYPE_BASE, PROTOTYPE_PLATFORM, stewart_prototype

MINIMAL = ("name: my-hexapod\n"
           "legs:            # exactly 6 for a hexapod; mm\n"
           + PROTOTYPE_LEGS_YAML
           + "limits: {u_joint_tilt: 45, s_joint_tilt: 29, leg_diameter: 36.1}   # degrees, mm; optional\n")


def _error(text: str) -> InputFileError:
    with pytest.raises(InputFileError) as info:
        machine_from_text(text, "m.yaml")
    return info.value


def _with_leg(text: str, leg: int, new: str) -> str:
    lines = text.splitlines()
    lines[2 + leg] = "  - " + new
    return "\n".join(lines) + "\n"


# -- the minimal form --------------------------------------------------------------------

def test_minimal_form_is_the_prototype():
    m = machine_from_text(MINIMAL, "m.yaml")
    ref = stewart_prototype()
    assert isinstance(m, Hexapod)
    assert m.name == "my-hexapod"
    np.testing.assert_array_equal(m.base, PROTOTYPE_BASE)
    np.testing.assert_array_equal(m.platform, PROTOTYPE_PLATFORM)
    assert m.limits == ref.limits  # degrees in the file, exactly np.deg2rad inside
    assert replace(m, name=ref.name, description=ref.description) == ref


def test_name_defaults_to_file_stem(tmp_path):
    path = tmp_path / "bench-7.yaml"
    path.write_text(MINIMAL.replace("name: my-hexapod\n", ""))
    assert load_machine(str(path)).name == "bench-7"


def test_optional_keys(tmp_path):
    text = MINIMAL + """\
kind: hexapod
description: test bench
home: {x: 1, y: 2, z: 320, a: 1.5, b: -2, c: 90}
workspace: {x: [-10, 10], y: [-10, 10], z: [300, 330], a: [-5, 5], b: [-5, 5], c: [-30, 30]}
uncertainty:
  parameters: [b1.x, L0_2]
  std: {b1.x: 0.02, L0_2: 0.05}
  correlation: [[1, 0.5], [0.5, 1]]
calibration: {method: ik-residual, date: 2024-05-01, n_poses: 30, residual_rms: 0.004}
"""
    m = machine_from_text(text, "m.yaml")
    np.testing.assert_array_equal(m.home, [1, 2, 320, np.deg2rad(1.5), np.deg2rad(-2), np.deg2rad(90)])
    assert m.workspace[5, 1] == np.deg2rad(30.0)
    i, j = HEXAPOD_PARAM_NAMES.index("b1.x"), HEXAPOD_PARAM_NAMES.index("L0_2")
    assert m.covariance[i, i] == pytest.approx(0.02**2, rel=1e-15)
    assert m.covariance[i, j] == pytest.approx(0.5 * 0.02 * 0.05, rel=1e-15)
    assert np.count_nonzero(m.covariance) == 4
    assert m.metadata["calibration"]["n_poses"] == 30
    path = tmp_path / "out.yaml"
    save_machine(m, path)
    back = load_machine(str(path))
    assert back == m
    assert back.metadata == m.metadata


def test_axes_are_normalised_and_round_trip():
    text = _with_leg(MINIMAL, 2, "{base: [76.25, -132.068, 0], platform: [0, -70, 0], offset: 305.0, "
                                 "stroke: [0, 50], base_axis: [1, 2, 3], platform_axis: [0, 0.6, 0.8]}")
    m = machine_from_text(text, "m.yaml")
    np.testing.assert_allclose(m.base_axis[2], np.array([1, 2, 3]) / math.sqrt(14), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(m.base_axis[0], [0, 0, 1])
    assert machine_from_text(machine_to_text(m)) == m


@pytest.mark.parametrize("name", ["stewart-prototype", "stewart-prototype-real",
                                  "symmetric:platform_separation=0,leg_diameter=20"])
def test_builtin_round_trip(tmp_path, name):
    m = load_machine(name)
    path = tmp_path / "m.yaml"
    save_machine(m, path)
    assert load_machine(str(path)) == m
    assert sorted(os.listdir(tmp_path)) == ["m.yaml"]  # no temporary files left behind
    text1 = path.read_bytes()
    save_machine(load_machine(str(path)), path)
    assert path.read_bytes() == text1  # deterministic bytes


def test_save_is_readable_yaml_with_degrees():
    data = yaml.safe_load(machine_to_text(load_machine("stewart-prototype")))
    assert data["limits"]["u_joint_tilt"] == 45.0
    assert data["legs"][0]["base"] == [-152.5, 0.0, 0.0]
    assert "home" not in data  # the default home is not written


def test_existing_file_wins_over_builtin_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "stewart-prototype").write_text(MINIMAL)
    assert load_machine("stewart-prototype").name == "my-hexapod"


def test_save_keeps_permissions(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text("old")
    os.chmod(path, 0o640)
    save_machine(stewart_prototype(), path)
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o640


def test_save_refuses_unloadable_machine_and_writes_nothing(tmp_path):
    cov = np.zeros((48, 48))
    cov[0, 0], cov[1, 1], cov[0, 1], cov[1, 0] = 1.0, 1.0, 2.0, 2.0  # not positive semi-definite
    m = replace(stewart_prototype(), covariance=cov)
    with pytest.raises(PkmcalError, match="cannot save machine .*correlations must lie in"):
        save_machine(m, tmp_path / "m.yaml")
    assert os.listdir(tmp_path) == []


# -- exact degrees ---------------------------------------------------------------------------

@settings(max_examples=400, deadline=None)
@given(st.floats(min_value=-10.0, max_value=10.0, allow_nan=False).filter(lambda v: v == 0 or abs(v) > 1e-300))
def test_degree_text_converts_back_exactly(rad):
    text = rad_to_deg_text(rad)
    data, _ = parse_yaml(f"v: {text}\n")
    assert isinstance(data["v"], TextFloat)
    assert deg_to_rad(data["v"]) == rad
    assert abs(float(text) - np.rad2deg(rad)) <= 1e-12 * max(1.0, abs(np.rad2deg(rad)))


def test_round_degrees_are_short():
    for d in (0.0, 1.0, 29.0, 45.0, -90.0, 180.0, 12.5):
        assert rad_to_deg_text(np.deg2rad(d)) == repr(d)


# -- hypothesis round trips over random machines -------------------------------------------

coord = st.floats(min_value=-1e4, max_value=1e4, allow_nan=False)
angle = st.floats(min_value=-3.5, max_value=3.5, allow_nan=False)


def _pair(elem):
    return st.tuples(elem, elem).map(sorted)


unit_ish = st.tuples(*[st.floats(-1, 1, allow_nan=False)] * 3).filter(lambda v: np.linalg.norm(v) > 1e-3)
#: One-line text: names and descriptions hold no control characters (pkmcal.errors.line_problem).
one_line_text = st.text(st.characters(blacklist_categories=("Cc", "Cs", "Zl", "Zp")), max_size=30)
json_scalar = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6),
                        st.floats(allow_nan=False, allow_infinity=False), st.text(max_size=20))
json_like = st.recursive(json_scalar, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.text(min_size=1, max_size=8), inner, max_size=4)), max_leaves=12)


@st.composite
def machines(draw) -> Hexapod:
    base = draw(st.lists(st.tuples(coord, coord, coord), min_size=6, max_size=6))
    platform = draw(st.lists(st.tuples(coord, coord, coord), min_size=6, max_size=6))
    offset = draw(st.lists(st.floats(1e-3, 1e4), min_size=6, max_size=6))
    stroke = draw(st.lists(_pair(st.floats(-100, 100)), min_size=6, max_size=6))
    axes = lambda: draw(st.one_of(st.none(), st.lists(unit_ish, min_size=6, max_size=6)))  # noqa: E731
    tilt = st.one_of(st.none(), st.floats(1e-3, 3.14159))
    limits = HexapodLimits(u_joint_tilt=draw(tilt), s_joint_tilt=draw(tilt),
                           leg_diameter=draw(st.one_of(st.none(), st.floats(0, 100))),
                           singularity_margin=draw(st.floats(0, 0.99)))
    home = draw(st.one_of(st.none(), st.tuples(coord, coord, coord, angle, angle, angle)))
    workspace = draw(st.one_of(st.none(), st.tuples(*([_pair(coord)] * 3 + [_pair(angle)] * 3))))
    covariance = None
    if draw(st.booleans()):
        k = draw(st.integers(0, 8))
        idx = draw(st.lists(st.integers(0, 47), min_size=k, max_size=k, unique=True))
        a = np.array(draw(st.lists(st.floats(-1, 1), min_size=k * k, max_size=k * k))).reshape(k, k)
        block = a @ a.T
        covariance = np.zeros((48, 48))
        covariance[np.ix_(idx, idx)] = (block + block.T) / 2
    metadata = draw(st.dictionaries(st.text(min_size=1, max_size=8), json_like, max_size=3))
    gains = draw(st.one_of(st.none(), st.lists(st.one_of(st.just(1.0), st.floats(1e-6, 1e4)), min_size=6,
                                                 max_size=6)))
    unit = draw(st.sampled_from(["mm", "rev", "count", "motor deg", "µm"]))
    return Hexapod(name=draw(one_line_text), base=base, platform=platform, offset=offset, stroke=stroke,
                   base_axis=axes(), platform_axis=axes(), limits=limits, home=home, workspace=workspace,
                   covariance=covariance, description=draw(one_line_text), metadata=metadata, gains=gains,
                   actuator_unit=unit)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(machines())
def test_random_machines_round_trip_exactly(m):
    text = machine_to_text(m)
    back = machine_from_text(text, "m.yaml")
    assert back == m
    assert back.metadata == m.metadata
    assert machine_to_text(back) == text


def test_round_trip_through_files(tmp_path):
    rng = np.random.default_rng(3)
    m = load_machine("stewart-prototype-real")
    m = m.with_params(m.params + np.r_[rng.normal(0, 1e-3, 42), np.zeros(6)], name="identified")
    a = rng.normal(size=(42, 42)) * 1e-3
    cov = np.zeros((48, 48))
    cov[:42, :42] = a @ a.T  # the gains held: zero rows
    m = replace(m, covariance=cov, metadata={"calibration": {"method": "fk-residual", "n_poses": 40}})
    path = tmp_path / "identified.yaml"
    save_machine(m, path)
    back = read_machine_file(path)
    assert back == m
    assert back.metadata == m.metadata


@settings(max_examples=150, deadline=None)
@given(k=st.integers(1, 8), seed=st.integers(0, 2**32 - 1), log_scale=st.floats(-8, 4))
def test_written_std_and_correlation_agree_with_the_covariance(k, seed, log_scale):
    """The file's σ and ρ, against the written Σ computed independently: σ_i = √Σ_ii,
    ρ_ij = Σ_ij / √(Σ_ii Σ_jj) to 1e-12, exactly symmetric, ones on the diagonal."""
    rng = np.random.default_rng(seed)
    idx = rng.choice(48, size=k, replace=False)
    a = rng.normal(size=(k, k)) * 10.0 ** (log_scale + rng.uniform(-2, 2, (k, 1)))
    cov = np.zeros((48, 48))
    cov[np.ix_(idx, idx)] = a @ a.T
    cov = (cov + cov.T) / 2
    data = yaml.safe_load(machine_to_text(replace(stewart_prototype(), covariance=cov)))["uncertainty"]
    names = data["parameters"]
    assert sorted(names, key=HEXAPOD_PARAM_NAMES.index) == names == [HEXAPOD_PARAM_NAMES[i] for i in sorted(idx)]
    sub = np.array(data["covariance"], dtype=float)
    np.testing.assert_array_equal(sub, cov[np.ix_(sorted(idx), sorted(idx))])
    np.testing.assert_allclose([data["std"][n] for n in names], np.sqrt(np.diag(sub)), rtol=1e-15, atol=0)
    corr = np.array(data["correlation"], dtype=float)
    expect = sub / np.sqrt(np.outer(np.diag(sub), np.diag(sub)))
    np.testing.assert_allclose(corr, expect, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(corr, corr.T)
    assert np.all(np.diag(corr) == 1.0)


# -- errors ----------------------------------------------------------------------------------

def test_five_legs():
    text = "\n".join(line for i, line in enumerate(MINIMAL.splitlines()) if i != 4) + "\n"
    err = _error(text)
    assert "m.yaml" in str(err)
    assert "legs: 5 legs given, a hexapod needs exactly 6" in str(err)
    assert err.line == 2


def test_stroke_reversed_names_path_leg_and_line():
    text = _with_leg(MINIMAL, 3, "{base: [132.068, -76.25, 0], platform: [70, 0, 0], offset: 305.0, stroke: [50, 0]}")
    err = _error(text)
    msg = str(err)
    assert "legs[3].stroke (leg 4)" in msg and "max < min" in msg and "[min, max]" in msg
    assert err.line == 6
    assert msg.startswith("m.yaml, line 6: ")


@pytest.mark.parametrize(
    "leg, expected",
    [
        ("{base: [1, 2], platform: [0, -70, 0], offset: 305.0, stroke: [0, 50]}",
         "legs[0].base (leg 1): expected 3 numbers [x, y, z] (mm), got 2 items"),
        ("{base: [1, 2, x], platform: [0, -70, 0], offset: 305.0, stroke: [0, 50]}",
         "legs[0].base[2] (leg 1): expected a number, got 'x'"),
        ("{base: [1, 2, .nan], platform: [0, -70, 0], offset: 305.0, stroke: [0, 50]}",
         "legs[0].base[2] (leg 1): expected a finite number"),
        ("{base: [1, 2, 3], platform: [0, -70, 0], stroke: [0, 50]}",
         "legs[0] (leg 1): missing key 'offset'"),
        ("{base: [1, 2, 3], platform: [0, -70, 0], offset: 305.0, strok: [0, 50]}",
         "legs[0] (leg 1): missing key 'stroke'"),
        ("{base: [1, 2, 3], platform: [0, -70, 0], offset: -5, stroke: [0, 50]}",
         "legs[0].offset (leg 1): -5.0 mm is not a leg offset"),
        ("{base: [1, 2, 3], platform: [0, -70, 0], offset: '305', stroke: [0, 50]}",
         "legs[0].offset (leg 1): expected a number, got '305'"),
        ("{base: [1, 2, 3], platform: [0, -70, 0], offset: true, stroke: [0, 50]}",
         "legs[0].offset (leg 1): expected a number, got True"),
        ("{base: [1, 2, 3], platform: [0, -70, 0], offset: 305, stroke: [0, 50], base_axis: [0, 0, 0]}",
         "legs[0].base_axis (leg 1): a joint axis cannot be the zero vector"),
        ("[1, 2, 3]", "legs[0] (leg 1): expected a mapping"),
    ],
)
def test_leg_errors(leg, expected):
    err = _error(_with_leg(MINIMAL, 0, leg))
    assert expected in str(err)
    assert err.line == 3


def test_unknown_key_suggests():
    err = _error(MINIMAL.replace("leg_diameter", "leg_diametre"))
    assert "limits.leg_diametre: unknown key 'leg_diametre'; did you mean 'leg_diameter'?" in str(err)
    assert err.line == 9


@pytest.mark.parametrize(
    "text, expected, line",
    [
        ("", "the file is empty", None),
        ("# only a comment\n", "the file is empty", None),
        ("- 1\n- 2\n", "expected a mapping of 'key: value' lines", 1),
        ("name: x\nlegs: [\n", "not valid YAML", 3),
        ("name: x\n  legs: 1\n", "not valid YAML", 2),
        ("name: a\nname: b\n", "key 'name' appears twice (lines 1 and 2)", 2),
        ("kind: planar\nname: x\n", "kind: 'planar' is not a known machine kind; known kinds: hexapod", 1),
        ("name: x\n", "top level: missing key 'legs'", 1),
        ("name: x\nlegs: 6\n", "legs: expected a list, got 6", 2),
        ("name: x\nlegs: []\n", "legs: 0 legs given", 2),
        ("name: 12\nlegs: []\n", "name: expected text, got 12", 1),
        ("name: !!python/object:os.system x\n", "not valid YAML", 1),
    ],
)
def test_file_level_errors(text, expected, line):
    err = _error(text)
    assert expected in str(err)
    assert err.line == line
    assert "\n" not in str(err)


@pytest.mark.parametrize(
    "block, expected",
    [
        ("limits: {u_joint_tilt: 200}", "limits.u_joint_tilt: 200.0° is not a joint tilt limit"),
        ("home: {x: 0, y: 0, z: 300}", "home: missing key 'a'"),
        ("workspace: {x: [1, -1], y: [0, 1], z: [0, 1], a: [0, 1], b: [0, 1], c: [0, 1]}",
         "workspace.x: [1.0, -1.0] has max < min"),
        ("uncertainty: {std: {b9.x: 0.1}}", "uncertainty.std['b9.x']: unknown parameter 'b9.x'"),
        ("uncertainty: {std: {b1.x: -0.1}}", "uncertainty.std['b1.x']: a standard deviation cannot be negative"),
        ("uncertainty: {std: {b1.x: 1.0e+200}}", "the covariance overflows"),
        ("uncertainty: {parameters: [b1.x, b1.y], std: {b1.x: 0.1}}", "no standard deviation for b1.y"),
        ("uncertainty: {parameters: [b1.x, b1.y], std: {b1.x: 0.1, b1.y: 0.1}, correlation: [[1, 0]]}",
         "uncertainty.correlation: 1 rows, need 2"),
        ("uncertainty: {parameters: [b1.x, b1.y], std: {b1.x: 0.1, b1.y: 0.1}, correlation: [[1, 2], [2, 1]]}",
         "correlations must lie in [-1, 1]"),
        ("uncertainty: {parameters: [b1.x, b1.y, b1.z], std: {b1.x: 1, b1.y: 1, b1.z: 1}, "
         "correlation: [[1, 0.9, -0.9], [0.9, 1, 0.9], [-0.9, 0.9, 1]]}", "not positive semi-definite"),
        ("uncertainty: {parameters: [b1.x], std: {b1.x: 0.1}, covariance: [[0.04]]}",
         "uncertainty.std: disagrees with the square roots of the covariance diagonal"),
        ("calibration: [1, 2]", "calibration: expected a mapping"),
    ],
)
def test_optional_block_errors(block, expected):
    if block.startswith("limits:"):
        text, line = MINIMAL.replace(MINIMAL.splitlines()[-1], block), 9
    else:
        text, line = MINIMAL + block + "\n", 10
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)   # the message, not NumPy's warning first
        err = _error(text)
    assert expected in str(err)
    assert err.line == line


def test_file_errors(tmp_path):
    with pytest.raises(InputFileError, match="no such machine file"):
        load_machine(str(tmp_path / "missing.yaml"))
    with pytest.raises(InputFileError, match="cannot read the machine file"):
        load_machine(str(tmp_path))
    bad = tmp_path / "bad.yaml"
    bad.write_bytes(b"name: \xff\xfe\x00")
    with pytest.raises(InputFileError, match="not a UTF-8 text file"):
        load_machine(str(bad))
    with pytest.raises(PkmcalError, match="unknown machine 'nonesuch'"):
        load_machine("nonesuch")


def test_anchors_allowed_but_alias_bombs_and_cycles_rejected():
    text = MINIMAL.replace("stroke: [0, 50]}", "stroke: &s [0, 50]}", 1)
    text = text.replace("platform: [0, -70, 0], offset: 305.0, stroke: [0, 50]}",
                        "platform: [0, -70, 0], offset: 305.0, stroke: *s}")
    assert machine_from_text(text) == machine_from_text(MINIMAL)
    bomb = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
        f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join(['*' + chr(97 + i)] * 9)}]\n" for i in range(8))
    assert "aliases expand to more than 1000000 values" in str(_error(bomb + "calibration: {z: *i}\n"))
    assert "recursive structure" in str(_error("a: &a [*a]\n"))


# -- planar machines (kinds planar-2dof-3act, planar-3dof-4act) ---------------------------


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kind=st.sampled_from(["planar-2dof-3act", "planar-3dof-4act"]),
       seed=st.integers(0, 2**31 - 1), scale=st.sampled_from([1e-9, 1e-3, 0.3]), with_cov=st.booleans())
def test_planar_machine_file_round_trip_is_exact(kind, seed, scale, with_cov):
    from pkmcal.mechanisms.library import builtin_machine

    m = builtin_machine(kind)
    rng = np.random.default_rng(seed)
    p = m.params + rng.normal(size=m.params.shape) * scale
    cov = None
    if with_cov:
        A = rng.normal(size=(len(p), len(p))) * scale
        cov = A @ A.T
        cov[1, :] = cov[:, 1] = 0.0          # a fixed (gauge) parameter
    m2 = replace(m.with_params(p, name="rt", covariance=cov), metadata={"calibration": {"method": "projection"}})
    back = machine_from_text(machine_to_text(m2))
    assert type(back) is type(m2) and back == m2
    assert np.array_equal(back.params, p)
    assert (back.covariance is None) == (cov is None)
    if cov is not None:
        assert np.array_equal(back.covariance, cov)
    assert back.metadata == m2.metadata


def test_planar_machine_file_angles_are_degrees(tmp_path):
    from pkmcal.mechanisms.library import builtin_machine

    m = builtin_machine("planar-2dof-3act")
    m2 = m.with_deltas({"dq1": np.deg2rad(0.5), "l11": 0.25})
    text = machine_to_text(m2)
    assert "dq1: 0.5\n" in text and "l11: 280.25\n" in text
    m4 = builtin_machine("planar-3dof-4act").with_deltas({"alpha2": np.deg2rad(-0.065), "dq3": 0.5})
    text4 = machine_to_text(m4)
    assert "alpha2: -0.065\n" in text4 and "dq3: 0.5\n" in text4      # linear encoder offsets stay mm
    path = tmp_path / "m.yaml"
    save_machine(m2, path)
    assert load_machine(path) == m2


def test_planar_machine_file_hand_written_defaults():
    text = """kind: planar-3dof-4act
name: hand
parameters: {L3: 230, y1: 0, y2: 460, alpha1: 0, alpha2: 0.5, rho11: 340, rho12: 340, rho21: 340,
             rho22: 340, dq1: 0, dq2: 0, dq3: 0, dq4: 0}
limits: {min_leg_angle: 20}
"""
    m = machine_from_text(text)
    assert m.name == "hand" and m.p("alpha2") == np.deg2rad(0.5)
    assert m.min_leg_angle == np.deg2rad(20.0)
    ref = load_machine("planar-3dof-4act")
    assert np.array_equal(m.home, ref.home) and np.array_equal(m.workspace, ref.workspace)


@pytest.mark.parametrize("body, where, words", [
    ("parameters: {l11: 280}", "parameters", "missing l12"),
    ("parameters: {l11: 280, l12: 280, l21: 280, l22: 280, l31: 280, l32: 280, B1.x: -300, B1.y: 0, B2.x: 300, "
     "B2.y: 0, B3.x: 150, B3.y: 420, D1: 215, D2: 215, D3: 215, dq1: 0, dq2: 0, dq3: 0, D4: 1}", "parameters.D4",
     "unknown parameter"),
    ("parameters: {l11: x}", "parameters", "expected a number"),
    ("limits: {min_leg_angle: 10}\nparameters: {l11: 280, l12: 280, l21: 280, l22: 280, l31: 280, l32: 280, "
     "B1.x: -300, B1.y: 0, B2.x: 300, B2.y: 0, B3.x: 150, B3.y: 420, D1: 215, D2: 215, D3: 215, dq1: 0, dq2: 0, "
     "dq3: 0}", "limits.min_leg_angle", "min_transmission"),
])
def test_planar_machine_file_errors(body, where, words):
    with pytest.raises(InputFileError) as exc:
        machine_from_text("kind: planar-2dof-3act\n" + body + "\n", "bad.yaml")
    msg = str(exc.value)
    assert "bad.yaml" in msg and words in msg and where.split(".")[0] in msg


def test_planar_machine_file_uncertainty_std_in_degrees():
    from pkmcal.mechanisms.library import builtin_machine

    m = builtin_machine("planar-2dof-3act")
    cov = np.zeros((18, 18))
    cov[15, 15] = np.deg2rad(0.01) ** 2       # dq1: 0.01 deg
    cov[0, 0] = 0.02 ** 2                    # l11: 0.02 mm
    text = machine_to_text(m.with_params(m.params, covariance=cov))
    data, _ = parse_yaml(text)
    assert math.isclose(data["uncertainty"]["std"]["dq1"], 0.01, rel_tol=1e-12)
    assert math.isclose(data["uncertainty"]["std"]["l11"], 0.02, rel_tol=1e-12)
    # std and correlation alone (no covariance) rebuild it in internal units
    hand = text.split("  covariance:")[0]
    back = machine_from_text(hand)
    np.testing.assert_allclose(back.covariance, cov, rtol=1e-12, atol=0)
