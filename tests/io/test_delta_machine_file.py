"""Machine files of the deltas (pkmcal.io.delta_machine_file) and their built-ins: exact
save/load round trips (angles in degrees, covariance included), errors naming the file,
line and key, and the built-ins' documented dimensions."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pkmcal.errors import InputFileError
from pkmcal.io.machine_file import load_machine, machine_from_text, machine_to_text, save_machine
from pkmcal.mechanisms.linear_delta import LinearDelta
from pkmcal.mechanisms.rotary_delta import RotaryDelta

_small = st.floats(-1, 1, allow_nan=False, allow_infinity=False)


def _perturbed(m, draw, scale):
    rho = m.params + np.array(draw(st.lists(_small, min_size=len(m.params), max_size=len(m.params)))) * scale
    A = np.array(draw(st.lists(_small, min_size=4 * len(rho), max_size=4 * len(rho)))).reshape(4, len(rho))
    return m.with_params(rho, name="drawn", covariance=A.T @ A + 1e-6 * np.eye(len(rho)))


@settings(max_examples=25, deadline=None)
@given(data=st.data())
def test_linear_delta_round_trip_is_exact(tmp_path_factory, data):
    scale = np.where(load_machine("kossel-mini").param_is_angle, np.deg2rad(1.0), 2.0)
    m = _perturbed(load_machine("kossel-mini"), data.draw, scale)
    path = tmp_path_factory.mktemp("m") / "delta.yaml"
    save_machine(m, path)
    back = load_machine(str(path))
    assert isinstance(back, LinearDelta) and back == m
    np.testing.assert_array_equal(back.covariance, m.covariance)
    np.testing.assert_array_equal(back.reading_reference, m.reading_reference)


@settings(max_examples=25, deadline=None)
@given(data=st.data())
def test_rotary_delta_round_trip_is_exact(tmp_path_factory, data):
    scale = np.where(load_machine("delta-picker").param_is_angle, np.deg2rad(1.0), 2.0)
    m = _perturbed(load_machine("delta-picker"), data.draw, scale)
    path = tmp_path_factory.mktemp("m") / "picker.yaml"
    save_machine(m, path)
    back = load_machine(str(path))
    assert isinstance(back, RotaryDelta) and back == m
    np.testing.assert_array_equal(back.covariance, m.covariance)


def test_kossel_mini_has_marlins_example_dimensions():
    m = load_machine("kossel-mini")
    assert m.kind == "linear-delta" and m.print_radius == 90.0
    # at the centre, on the bed: every carriage sqrt(rod² − radius²) above the nozzle
    np.testing.assert_allclose(m.ik([0.0, 0.0, 0.0]), [[np.sqrt(215.0**2 - 105.2**2)] * 3], rtol=0, atol=1e-12)
    # homed (carriages at their switches): the nozzle at DELTA_HEIGHT
    np.testing.assert_allclose(m.fk(m.reading_reference).poses, [[0.0, 0.0, 250.0]], rtol=0, atol=1e-9)


def test_delta_picker_reaches_its_workspace():
    m = load_machine("delta-picker")
    assert m.kind == "rotary-delta"
    rng = np.random.default_rng(0)
    r, phi = m.workspace_radius * np.sqrt(rng.uniform(size=500)), rng.uniform(0, 2 * np.pi, 500)
    p = np.stack([r * np.cos(phi), r * np.sin(phi), rng.uniform(*m.z_range, 500)], axis=1)
    rim = m.workspace_radius * (1 - 1e-9)     # on the rim, inside by more than rounding
    p = np.vstack([p, [[rim * np.cos(t), rim * np.sin(t), z] for t in np.deg2rad(np.arange(0, 360, 5))
                       for z in (m.z_range[0] + 1e-9, m.z_range[1] - 1e-9)]])
    assert m.check_limits(p).ok.all()
    np.testing.assert_allclose(m.fk(m.ik(p)).poses, p, rtol=0, atol=1e-9)


LINEAR = """\
kind: linear-delta
name: mine
towers:
  a: {angle: 210, radius: 105.2, arm: 215, endstop: 250}
  b: {angle: 330, radius: 105.2, arm: 215, endstop: 250}
  c: {angle: 90, radius: 105.2, arm: 215, endstop: 250}
"""


def test_minimal_file_takes_the_defaults():
    m = machine_from_text(LINEAR, "mine.yaml")
    kossel = load_machine("kossel-mini")
    assert m.name == "mine"
    np.testing.assert_array_equal(m.params, kossel.params)
    np.testing.assert_array_equal(m.reading_reference, kossel.reading_reference)
    assert (m.print_radius, m.min_z, m.min_arm_angle) == (85.0, 0.0, np.deg2rad(20.0))   # the class defaults
    assert "kind: linear-delta" in machine_to_text(m)


@pytest.mark.parametrize("text, message", [
    (LINEAR.replace("  c: {angle: 90, radius: 105.2, arm: 215, endstop: 250}\n", ""), "towers: missing c"),
    (LINEAR.replace("arm: 215, endstop: 250}\n  c", "arm: 95, endstop: 250}\n  c"),
     "line 5: towers: arm_b must be longer than radius_b"),
    (LINEAR.replace("radius: 105.2, arm: 215, endstop: 250}\n  b", "radius: '105.2', arm: 215, endstop: 250}\n  b"),
     "line 4"),
    (LINEAR + "limits: {print_radius: 90, colour: red}\n", "colour"),
    (LINEAR.replace("  a:", "  d:"), "towers"),
])
def test_bad_files_name_the_line_and_key(text, message):
    with pytest.raises(InputFileError, match=message):
        machine_from_text(text, "mine.yaml")
