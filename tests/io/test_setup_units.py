"""Setup files state the unit of the full-pose orientation noise explicitly (degrees, as every
angle in files), and older files keep their meaning (docs/conventions.md, "Units")."""

from __future__ import annotations

import numpy as np
import pytest

from pkmcal.io.setup_file import load_setup, setup_to_yaml
from pkmcal.sensors.library import builtin_setup

OLD = "sensor: full-pose\nnoise: {distribution: uniform, position: 0.025, orientation: 0.001, actuator: 0.01}\n"
NEW = ("sensor: full-pose\nnoise: {distribution: uniform, position: 0.025, orientation_deg: 0.05729577951308232, "
       "actuator: 0.01}\n")


def test_written_in_degrees_and_read_back_exactly(tmp_path):
    """Old behaviour: the writer put the orientation noise in radians under 'orientation'
    with a header saying so, against the rule 'degrees in files'."""
    setup = builtin_setup("full-pose-paper1")
    text = setup_to_yaml(setup)
    assert "orientation_deg:" in text and "orientation:" not in text and "in rad" not in text
    (tmp_path / "s.yaml").write_text(text)
    back = load_setup(tmp_path / "s.yaml")
    assert np.array_equal(back.noise.reading_std, setup.noise.reading_std)
    deg = float(text.split("orientation_deg:")[1].split()[0])
    assert deg / np.sqrt(3.0) == pytest.approx(np.rad2deg(setup.noise.reading_std[3]), rel=1e-15)  # half-width, deg


def test_old_key_keeps_its_meaning(tmp_path):
    (tmp_path / "old.yaml").write_text(OLD)
    (tmp_path / "new.yaml").write_text(NEW)
    old, new = load_setup(tmp_path / "old.yaml"), load_setup(tmp_path / "new.yaml")
    np.testing.assert_allclose(old.noise.reading_std[3:], 0.001 / np.sqrt(3.0), rtol=1e-15)   # rad, as always
    np.testing.assert_allclose(new.noise.reading_std, old.noise.reading_std, rtol=1e-15)
