"""Correction files (pkmcal.compensation.files): written and read back to the same field (a
mesh bit for bit; a pose field's angle columns through degrees, to rounding), Klipper's
profile options as ProfileManager.save_profile writes them, and bad files refused in one
line naming the file, the line and the key."""

from __future__ import annotations

import numpy as np
import pytest

import pkmcal
from pkmcal.compensation.basis import MeshBasis, PolynomialBasis
from pkmcal.compensation.files import klipper_block, klipper_profile, load_correction, save_correction
from pkmcal.compensation.fit import Field
from pkmcal.errors import PkmcalError, PkmcalWarning

HEX = pkmcal.load_machine("stewart-prototype")
DELTA = pkmcal.load_machine("kossel-mini")


def _pose_field():
    home = HEX.home_pose
    box = tuple((h - 10.0, h + 10.0) for h in home[:3]) + tuple((-0.1, 0.1) for _ in range(3))
    basis = PolynomialBasis(2, box)
    coef = np.random.default_rng(1).normal(0.0, 0.01, (basis.size, 4))
    return Field("pose-field", basis, ("x", "z", "a", "c"), coef)


def _mesh():
    basis = MeshBasis(5, 4, ((-50.0, 70.0), (-40.0, 40.0)), "bicubic")
    return Field("bed-mesh", basis, ("bed_z",), np.random.default_rng(2).normal(0.0, 0.1, (20, 1)))


def test_pose_field_round_trip(tmp_path):
    fld = _pose_field()
    save_correction(tmp_path / "c.yaml", fld, HEX, {"accepted": True})
    back = load_correction(tmp_path / "c.yaml", HEX)
    assert back.components == fld.components and back.basis.degree == 2
    # degrees in the file for the angle columns and the angles' box: rounding of one conversion
    np.testing.assert_allclose(back.coefficients, fld.coefficients, rtol=4 * np.finfo(float).eps, atol=0)
    np.testing.assert_allclose(back.basis.box, fld.basis.box, rtol=4 * np.finfo(float).eps, atol=0)
    pts = HEX.home_pose + np.random.default_rng(3).normal(0.0, [3, 3, 3, 0.02, 0.02, 0.02], (50, 6))
    np.testing.assert_allclose(back.displacement(HEX, pts), fld.displacement(HEX, pts), rtol=1e-12, atol=1e-15)
    text = (tmp_path / "c.yaml").read_text()
    assert text.startswith("# pkmcal correction") and "accepted: true" in text


def test_mesh_round_trip_is_exact(tmp_path):
    fld = _mesh()
    save_correction(tmp_path / "m.yaml", fld, DELTA)
    back = load_correction(tmp_path / "m.yaml", DELTA)
    np.testing.assert_array_equal(back.coefficients, fld.coefficients)
    assert back.basis == fld.basis


def test_klipper_profile_options():
    fld = _mesh()
    opts = klipper_profile(fld, "pkmcal")["bed_mesh pkmcal"]
    assert list(opts) == ["version", "points", "x_count", "y_count", "mesh_x_pps", "mesh_y_pps", "algo", "tension",
                          "min_x", "max_x", "min_y", "max_y"]
    rows = opts["points"].split("\n")[1:]
    assert len(rows) == 4 and all(len(r.split(", ")) == 5 for r in rows)
    assert rows[0].startswith("  ") and float(rows[0].split(", ")[0]) == pytest.approx(fld.coefficients[0, 0],
                                                                                       abs=5e-7)
    block = klipper_block(fld)
    assert "#*# [bed_mesh default]" in block and "#*# points =" in block and "#*# \t  " in block
    with pytest.raises(PkmcalError, match="pose field"):
        klipper_profile(_pose_field())
    with pytest.raises(PkmcalError, match="one word"):
        klipper_profile(fld, "two words")


@pytest.mark.parametrize("edit, where", [
    (lambda t: t.replace("kind: bed-mesh", "kind: mesh"), ":2: kind"),
    (lambda t: t.replace("algo: bicubic", "algo: spline"), "basis.algo"),
    (lambda t: t.replace("x_count: 5", "x_count: 4"), "coefficients"),
    (lambda t: t.replace("x_count: 5", "x_count: five"), "basis.x_count"),
    (lambda t: t.replace("type: mesh", "type: spline"), "basis.type"),
    (lambda t: "just text\n", "not a correction file"),
])
def test_bad_files_are_one_line_errors(tmp_path, edit, where):
    save_correction(tmp_path / "m.yaml", _mesh(), DELTA)
    (tmp_path / "bad.yaml").write_text(edit((tmp_path / "m.yaml").read_text()))
    with pytest.raises(PkmcalError, match=where) as exc:
        load_correction(tmp_path / "bad.yaml", DELTA)
    assert "bad.yaml" in str(exc.value) and "\n" not in str(exc.value)


def test_a_correction_of_another_calibration_is_warned_about(tmp_path):
    from pkmcal.errors import PkmcalWarning

    save_correction(tmp_path / "m.yaml", _mesh(), DELTA)
    other = DELTA.with_params(DELTA.params, name="kossel-mini-2026-12-03")
    with pytest.warns(PkmcalWarning, match="fitted for machine 'kossel-mini'"):
        load_correction(tmp_path / "m.yaml", other)


def test_a_pose_field_for_another_machine_is_refused(tmp_path):
    save_correction(tmp_path / "p.yaml", _pose_field(), HEX)
    with pytest.raises(PkmcalError, match="basis.variables"), pytest.warns(PkmcalWarning):
        load_correction(tmp_path / "p.yaml", DELTA)
    with pytest.raises(PkmcalError, match="cannot read"):
        load_correction(tmp_path / "missing.yaml", HEX)
