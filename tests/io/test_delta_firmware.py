"""Klipper and Marlin delta configurations (pkmcal.io.delta_firmware): a real-style
printer.cfg with includes and a SAVE_CONFIG block, M503 output, the firmwares' formulas for
the tower positions and switch heights, exact round trips, and what an export drops."""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pkmcal.errors import InputFileError
from pkmcal.io.marlin_settings import MARLIN_ROUNDING, marlin_rounded
from pkmcal.io.delta_firmware import (
    KLIPPER_ROUNDING,
    klipper_rounded,
    rounding_effect,
    DeltaFirmware,
    RotaryFirmware,
    firmware_subset,
    klipper_text,
    marlin_text,
    read_klipper,
    read_klipper_printer,
    read_marlin,
    rotary_firmware_subset,
)
from pkmcal.mechanisms.linear_delta import PARAM_NAMES

PRINTER_CFG = """\
# Kossel-style delta, as Klipper's example-delta.cfg lays it out
[include mainsail.cfg]

[stepper_a]
step_pin: PF0
dir_pin: PF1
microsteps: 16
rotation_distance: 40
endstop_pin: ^PE4
homing_speed: 50
position_endstop: 297.05 ; measured
arm_length: 333.0

[stepper_b]
step_pin: PF6
rotation_distance: 40
endstop_pin: ^PJ0

[stepper_c]
step_pin: PL3
rotation_distance: 40
endstop_pin: ^PD2

[printer]
kinematics: delta
max_velocity: 300
max_accel: 3000
max_z_velocity: 150
delta_radius: 174.75
print_radius: 140
minimum_z_position: -5

[gcode_macro START_PRINT]
gcode:
    G28
    G1 Z10 F3000

#*# <---------------------- SAVE_CONFIG ---------------------->
#*# DO NOT EDIT THIS BLOCK OR BELOW. The contents are auto-generated.
#*#
#*# [printer]
#*# delta_radius = 174.210123
#*#
#*# [stepper_a]
#*# angle = 210.114221
#*# arm_length = 333.000000
#*# position_endstop = 296.681930
#*#
#*# [stepper_b]
#*# angle = 329.707221
#*# arm_length = 333.000000
#*# position_endstop = 297.383285
#*#
#*# [stepper_c]
#*# angle = 90.000000
#*# arm_length = 333.000000
#*# position_endstop = 296.917010
#*#
#*# [delta_calibrate]
#*# height0 = 0.0
#*# height0_pos = 23961.000,23961.000,23961.000
"""


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def test_klipper_config_with_include_and_saved_block(tmp_path):
    """klippy/configfile.py _strip_duplicates: an option of the #*# block that the main
    file also sets is commented out, so the main file's value is the one Klipper runs
    (changed from pkmcal's old reading, where the block won: radius 174.210123 and
    endstop_a 296.68193 were read although Klipper runs 174.75 and 297.05)."""
    _write(tmp_path, "mainsail.cfg", "[virtual_sdcard]\npath: ~/printer_data/gcodes\n")
    printer = read_klipper_printer(_write(tmp_path, "printer.cfg", PRINTER_CFG))
    fw = printer.firmware
    assert fw.radius == 174.75
    assert fw.angles_deg == (210.114221, 329.707221, 90.0)
    assert fw.arms == (333.0, 333.0, 333.0)
    assert fw.endstops == (297.05, 297.383285, 296.91701)
    assert fw.print_radius == 140.0 and fw.min_z == -5.0
    assert any("[printer] delta_radius, [stepper_a] arm_length, [stepper_a] position_endstop override" in n
               for n in printer.notes)


def test_the_example_printer_cfg_imports_to_what_klipper_runs():
    """examples/klipper/printer.cfg: Klipper runs delta_radius 174.75 and stepper_a's
    position_endstop 297.05 of the main file (pkmcal read 174.210 and 296.68 before)."""
    from pathlib import Path

    fw = read_klipper(str(Path(__file__).parents[2] / "examples" / "klipper" / "printer.cfg"))
    assert fw.radius == 174.75 and fw.endstops == (297.05, 297.383285, 296.91701)
    assert fw.angles_deg == (210.114221, 329.707221, 90.0)


_BLOCK = ("\n#*# <---------------------- SAVE_CONFIG ---------------------->\n"
          "#*# DO NOT EDIT THIS BLOCK OR BELOW. The contents are auto-generated.\n#*#\n"
          "#*# [printer]\n#*# delta_radius = 101.5\n#*#\n#*# [stepper_b]\n#*# angle = 331.25\n")
_MAIN = ("[printer]\nkinematics: delta\ndelta_radius: 100\n[stepper_a]\narm_length: 250 # mm\n"
         "position_endstop: 300\n")


@pytest.mark.parametrize("tail, block_read", [
    ("", True),                                   # the block as SAVE_CONFIG writes it
    ("\n\n\n", True),                             # trailing blank lines are stripped first
    ("[extra]\nkey: 1\n", False),                # anything after the block: the whole block ignored
    ("#*#x\n", False),                            # a '#*#' line without the space
    ("\n#*# [stepper_c]\n#*# angle = 91\n", False),   # a blank line inside the block
])
def test_saved_block_is_read_or_ignored_as_klipper_does(tmp_path, tail, block_read):
    """klippy/configfile.py _find_autosave_data: after the header every line must start
    with '#*# ' (or be '#*#'); otherwise Klipper ignores the whole block. The main file's
    delta_radius wins over the block's in any case."""
    printer = read_klipper_printer(_write(tmp_path, "printer.cfg", _MAIN + _BLOCK + tail))
    fw = printer.firmware
    assert fw.radius == 100.0
    assert fw.angles_deg == ((210.0, 331.25, 90.0) if block_read else (210.0, 330.0, 90.0))
    assert any("SAVE_CONFIG (#*#) block is ignored" in n for n in printer.notes) is not block_read


def test_a_saved_line_above_the_header_voids_the_block(tmp_path):
    text = _MAIN.replace("[stepper_a]", "#*# [stepper_b]\n[stepper_a]") + _BLOCK
    printer = read_klipper_printer(_write(tmp_path, "printer.cfg", text))
    assert printer.firmware.angles_deg == (210.0, 330.0, 90.0)
    assert any("line 4 starts with '#*# '" in n for n in printer.notes)


def test_include_is_applied_where_it_stands(tmp_path):
    """klippy/configfile.py _parse_config: the lines above an [include] are read first,
    then the included files (a glob, in sorted order, relative to the including file),
    then the lines below; later values win."""
    (tmp_path / "parts").mkdir()
    _write(tmp_path / "parts", "b.cfg", "[printer]\ndelta_radius: 103\n[stepper_a]\nangle: 211\n")
    _write(tmp_path / "parts", "a.cfg", "[printer]\ndelta_radius: 102\n[include ../more/c.cfg]\n")
    (tmp_path / "more").mkdir()
    _write(tmp_path / "more", "c.cfg", "[stepper_b]\nangle: 329\n")
    text = _MAIN + "[include parts/*.cfg]\n[include none/*.cfg]\n[printer]\ndelta_radius: 104\n"
    fw = read_klipper(_write(tmp_path, "printer.cfg", text))
    assert fw.radius == 104.0 and fw.angles_deg == (211.0, 329.0, 90.0)
    fw = read_klipper(_write(tmp_path, "printer.cfg", _MAIN + "[include parts/*.cfg]\n"))
    assert fw.radius == 103.0
    fw = read_klipper(_write(tmp_path, "printer.cfg", "[include parts/b.cfg]\n" + _MAIN))
    assert fw.radius == 100.0
    _write(tmp_path, "loop.cfg", "[include printer.cfg]\n")
    with pytest.raises(InputFileError, match="loops back"):
        read_klipper(_write(tmp_path, "printer.cfg", _MAIN + "[include loop.cfg]\n"))


def test_comments_as_klipper_strips_them(tmp_path):
    """A '#' anywhere ends the line (klippy/configfile.py _parse_config); ';' after white
    space (RawConfigParser inline_comment_prefixes)."""
    text = _MAIN.replace("delta_radius: 100", "delta_radius: 100#.5 ; comment")
    assert read_klipper(_write(tmp_path, "printer.cfg", text)).radius == 100.0


def test_probe_offsets_and_rotary_deltas(tmp_path):
    p = read_klipper_printer(_write(tmp_path, "printer.cfg", _MAIN + "[bltouch]\nx_offset: -2.5\nz_offset: 1.25\n"))
    assert p.probe_offset == (-2.5, 0.0, 1.25) and p.probe_section == "bltouch"
    with pytest.raises(InputFileError, match="probe.*z_offset"):
        read_klipper_printer(_write(tmp_path, "printer.cfg", _MAIN + "[probe]\nx_offset: 1\n"))
    with pytest.raises(InputFileError, match="one probe"):
        read_klipper_printer(_write(tmp_path, "printer.cfg", _MAIN + "[probe]\nz_offset: 1\n[bltouch]\nz_offset: 1\n"))
    rotary = ("[printer]\nkinematics: rotary_delta\nshoulder_radius: 33.9\nshoulder_height: 412.9\n"
              "[stepper_a]\nposition_endstop: 252\nupper_arm_length: 170\nlower_arm_length: 320\n"
              "[stepper_c]\nangle: 271\nposition_endstop: 250\n")
    fw = read_klipper(_write(tmp_path, "printer.cfg", rotary))
    assert fw == RotaryFirmware(33.9, 412.9, (30.0, 150.0, 271.0), (170.0,) * 3, (320.0,) * 3, (252.0, 252.0, 250.0))
    m = fw.machine("r")
    # each arm's reading is 0 (at its switch) with the nozzle at (0, 0, position_endstop)
    lam = m.ik(np.c_[np.zeros((3, 2)), fw.endstops])
    np.testing.assert_allclose(np.diag(lam), 0.0, rtol=0, atol=1e-12)
    back, dropped = rotary_firmware_subset(m)
    assert dropped == []
    np.testing.assert_allclose(back.endstops, fw.endstops, rtol=0, atol=1e-9)
    assert (back.shoulder_radius, back.upper_arms, back.angles_deg) == (33.9, fw.upper_arms, fw.angles_deg)


def test_travel_and_build_radius_are_klippers(tmp_path):
    """klippy/kinematics/delta.py: max_xy = min(print_radius, arm − radius,
    ratio_to_xy(12)); the lowest carriage Klipper commands is at minimum_z on the far edge,
    so a pose there uses the whole travel and one 1 mm lower is beyond it."""
    text = _MAIN.replace("[stepper_a]", "print_radius: 500\nminimum_z_position: -3\n[stepper_a]")
    fw = read_klipper(_write(tmp_path, "printer.cfg", text))
    r, arm = 100.0, 250.0
    ratio_xy = 12 * np.sqrt(arm**2 / 145.0) - r          # no step settings: the half-step term left out
    assert fw.print_radius == pytest.approx(ratio_xy, abs=1e-12)
    m = fw.machine("m")
    edge = np.array([[fw.print_radius * np.cos(np.deg2rad(30)), fw.print_radius * np.sin(np.deg2rad(30)), -3.0]])
    margins = m.check_limits(edge).margins
    assert margins["travel"][0] == pytest.approx(0.0, abs=1e-9)
    assert m.check_limits(edge - [0, 0, 1.0]).margins["travel"][0] < -0.5


def test_klipper_defaults_follow_stepper_a_and_the_standard_angles(tmp_path):
    fw = read_klipper(_write(tmp_path, "p.cfg", PRINTER_CFG.split("#*#")[0].replace("[include mainsail.cfg]", "")))
    assert fw.radius == 174.75
    assert fw.angles_deg == (210.0, 330.0, 90.0)
    assert fw.arms == (333.0,) * 3 and fw.endstops == (297.05,) * 3


def test_machine_has_klippers_towers_and_switch_heights(tmp_path):
    fw = read_klipper(_write(tmp_path, "p.cfg", PRINTER_CFG.replace("[include mainsail.cfg]", "")))
    m = fw.machine("kossel")
    # Klipper: towers at radius·(cos angle, sin angle); abs_endstop = position_endstop +
    # sqrt(arm² − radius²); stepper position z + sqrt(arm² − (x − x_t)² − (y − y_t)²)
    ang = np.deg2rad(fw.angles_deg)
    tx, ty = fw.radius * np.cos(ang), fw.radius * np.sin(ang)
    np.testing.assert_allclose(m.reading_reference, np.array(fw.endstops) + np.sqrt(333.0**2 - fw.radius**2),
                               rtol=0, atol=1e-12 * 600)
    p = np.array([[12.0, -30.0, 5.0], [0.0, 100.0, 40.0]])
    expected = p[:, 2:3] + np.sqrt(333.0**2 - (p[:, :1] - tx) ** 2 - (p[:, 1:2] - ty) ** 2)
    np.testing.assert_allclose(m.ik(p), expected, rtol=0, atol=1e-12 * 600)


_finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)


@st.composite
def firmwares(draw):
    r = draw(st.floats(50, 300))
    return DeltaFirmware(radius=r, angles_deg=tuple(a + draw(st.floats(-5, 5)) for a in (210.0, 330.0, 90.0)),
                         arms=tuple(r * draw(st.floats(1.5, 2.5)) for _ in range(3)),
                         endstops=tuple(draw(st.floats(100, 600)) for _ in range(3)),
                         print_radius=0.8 * r, min_z=0.0)


@settings(max_examples=50, deadline=None)
@given(fw=firmwares())
def test_round_trips_give_the_firmwares_rounded_numbers_exactly(tmp_path_factory, fw):
    d = tmp_path_factory.mktemp("rt")
    text = klipper_text(fw)
    # Klipper: every number as its SAVE_CONFIG writes it, "%.6f", and a comment line says so
    assert text.splitlines()[0] == f"# pkmcal: {KLIPPER_ROUNDING}"
    values = [line.split(" = ")[1] for line in text.splitlines() if " = " in line]
    assert len(values) == 10 and all(re.fullmatch(r"-?\d+\.\d{6}", v) for v in values), values
    cfg = "[printer]\nkinematics: delta\nprint_radius: {!r}\n\n".format(fw.print_radius) + text
    back = read_klipper(_write(d, "printer.cfg", cfg))
    r = klipper_rounded(fw)
    # the ten numbers exactly as rounded; each within half a unit of the 6th decimal of the
    # exact one (plus the decimal conversion's round-off of numbers below 1e3: 1.2e-13)
    numbers = lambda f: (f.radius, *f.angles_deg, *f.arms, *f.endstops)  # noqa: E731
    assert numbers(back) == numbers(r)
    np.testing.assert_allclose(numbers(r), numbers(fw), rtol=0, atol=0.5e-6 + np.spacing(1e3))
    assert back.print_radius <= fw.print_radius
    # machine → firmware numbers → machine (no text): lengths bit for bit; angles through one
    # radian → degree → radian conversion, each correctly rounded: within 2 ulp
    m = fw.machine("m")
    fw2, dropped = firmware_subset(m)
    assert dropped == []
    is_angle = np.array(m.param_is_angle)
    back_rho = fw2.machine("m").params
    np.testing.assert_array_equal(back_rho[~is_angle], m.params[~is_angle])
    np.testing.assert_allclose(back_rho[is_angle], m.params[is_angle], rtol=0, atol=2 * np.spacing(2 * np.pi))
    # Marlin: every word is the 32-bit float Marlin holds (the shortest decimal of it, at most
    # 6 decimals); the import gives marlin_rounded's numbers exactly
    gcode = marlin_text(fw)
    assert gcode.splitlines()[4] == f"; pkmcal: {MARLIN_ROUNDING}"
    words = re.findall(r"\b[A-Z](-?[\d.]+)", " ".join(gcode.splitlines()[1:3]))
    for w in words:
        assert float(np.float32(w)) == float(np.float32(float(w)))
        assert np.format_float_positional(np.float32(w), unique=True, trim="-") == w
        assert len(w.partition(".")[2]) <= 6
    mb = read_marlin(_write(d, "m503.txt", "echo:; Delta settings:\necho:  " + gcode.split("\n", 1)[1]))
    mr = marlin_rounded(fw)
    assert numbers(mb) == numbers(mr)
    # each number within the words' rounding of the exact ones: half a unit of the 6th decimal
    # and half the float32 spacing at 1e3 (3.1e-5) for each of the two words summed
    # (L + trim, H − adj, 210 + trim)
    np.testing.assert_allclose(numbers(mr), numbers(fw), rtol=0,
                               atol=2 * (0.5e-6 + 0.5 * float(np.spacing(np.float32(1e3)))))


def test_rounding_effect_is_the_largest_change_of_the_commanded_actuators():
    """rounding_effect against a hand-built case: a machine whose endstop is 1e-4 mm higher
    commands that carriage 1e-4 mm higher everywhere (carriage = z + sqrt(arm² − ρ²) + ...),
    so the largest change over the workspace is 1e-4 mm exactly (to round-off)."""
    from dataclasses import replace

    fw = DeltaFirmware(radius=105.2, angles_deg=(210.0, 330.0, 90.0), arms=(215.0,) * 3,
                       endstops=(250.0,) * 3, print_radius=90.0, min_z=0.0)
    moved = replace(fw, endstops=(250.0, 250.0001, 250.0))
    assert rounding_effect(fw.machine("a"), moved.machine("b")) == pytest.approx(1e-4, abs=1e-10)
    assert rounding_effect(fw.machine("a"), fw.machine("b")) == 0.0


def test_export_names_what_the_firmware_cannot_hold():
    fw = DeltaFirmware(radius=100.0, angles_deg=(210.0, 330.0, 90.0), arms=(215.0,) * 3, endstops=(300.0,) * 3)
    m = fw.machine("m")
    rho = m.params
    rho[PARAM_NAMES.index("lean_radial_b")] = np.deg2rad(0.3)
    rho[PARAM_NAMES.index("radius_c")] = 101.5
    fw2, dropped = firmware_subset(m.with_params(rho))
    names = [d.name for d in dropped]
    assert names == ["radius_a", "radius_b", "radius_c", "lean_radial_b"]
    assert fw2.radius == pytest.approx(100.5)
    assert "lean_radial_b = 0.3 deg cannot be represented" in dropped[-1].describe(True)


@pytest.mark.parametrize("text, message", [
    ("[printer]\nkinematics: cartesian\n", "kinematics is 'cartesian'"),
    ("[printer]\nkinematics: delta\n[stepper_a]\narm_length: 300\nposition_endstop: 290\n",
     "\\[printer\\] has no 'delta_radius'"),
    ("[printer]\nkinematics: delta\ndelta_radius: abc\n", "delta_radius: expected a number, got 'abc'"),
    ("[stepper_a]\nno section header problem\n", "line 2: not a Klipper config"),
    ("kinematics: delta\n", "line 1: not a Klipper config: an option before any"),
    ("[include missing.cfg]\n[printer]\nkinematics: delta\n", "no such file"),
])
def test_bad_klipper_configs_name_the_file_and_key(tmp_path, text, message):
    with pytest.raises(InputFileError, match=message):
        read_klipper(_write(tmp_path, "printer.cfg", text))


def test_bad_marlin_lines_name_the_line(tmp_path):
    with pytest.raises(InputFileError, match=r"line 2: cannot read"):
        read_marlin(_write(tmp_path, "m.gcode", "G28\nM665 L217 R95 H300 Q\n"))
    with pytest.raises(InputFileError, match="no M665 H value"):
        read_marlin(_write(tmp_path, "m.gcode", "M665 L217 R95\n"), "2.1.x")
    with pytest.raises(InputFileError, match="must be ≤ 0"):
        read_marlin(_write(tmp_path, "m.gcode", "M665 L217 R95 H300\nM666 X0.5\n"), "2.1.x", missing="zero")


def test_cli_klipper_and_marlin_both_ways(tmp_path):
    from click.testing import CliRunner

    from pkmcal.cli.main import cli
    from pkmcal.io.machine_file import load_machine

    run = CliRunner().invoke
    res = run(cli, ["export", "kossel-mini", "--format", "klipper", "-o", str(tmp_path / "saved.cfg")])
    assert res.exit_code == 0, res.output
    cfg = tmp_path / "printer.cfg"
    cfg.write_text("[printer]\nkinematics: delta\nprint_radius: 90\n\n" + (tmp_path / "saved.cfg").read_text())
    res = run(cli, ["import", "klipper", str(cfg), "-o", str(tmp_path / "k.yaml"), "--name", "kossel-mini"])
    assert res.exit_code == 0, res.output
    kossel, back = load_machine("kossel-mini"), load_machine(str(tmp_path / "k.yaml"))
    np.testing.assert_array_equal(back.params, kossel.params)
    np.testing.assert_array_equal(back.reading_reference, kossel.reading_reference)
    res = run(cli, ["export", "kossel-mini", "--format", "marlin", "-o", str(tmp_path / "m.gcode")])
    assert res.exit_code == 0, res.output
    # Marlin 2.1.x by default (2.0.6 on): H 0.5 mm below the lowest switch, so that homing moves every
    # M666 (it skips adjustments of MIN_STEPS_PER_SEGMENT steps or fewer; was H250, M666 X0 Y0 Z0)
    assert (tmp_path / "m.gcode").read_text().splitlines()[:3] == [
        "; Marlin 2.0.6-2.1.x: M665 L R H S X Y Z A B C", "M665 L215 R105.2 H249.5 X0 Y0 Z0 A0 B0 C0",
        "M666 X-0.5 Y-0.5 Z-0.5"]
    res = run(cli, ["import", "marlin", str(tmp_path / "m.gcode"), "-o", str(tmp_path / "m.yaml")])
    assert res.exit_code == 0, res.output
    np.testing.assert_allclose(load_machine(str(tmp_path / "m.yaml")).params, kossel.params, rtol=0, atol=1e-12)
    # a parameter the firmware cannot hold is named on stderr; a hexapod is refused
    rho = kossel.params
    rho[PARAM_NAMES.index("lean_tangential_c")] = np.deg2rad(0.2)
    from pkmcal.io.machine_file import save_machine

    save_machine(kossel.with_params(rho), tmp_path / "leaning.yaml")
    res = run(cli, ["export", str(tmp_path / "leaning.yaml"), "--format", "klipper"])
    assert res.exit_code == 0 and "lean_tangential_c = 0.2 deg cannot be represented" in res.output
    res = run(cli, ["export", "stewart-prototype", "--format", "marlin"])
    assert res.exit_code == 2 and "exports linear delta printers" in res.output


def test_unequal_radii_on_vertical_rails_are_rewritten_exactly():
    """Issue 13: the circumcentre rewrite (io/delta_firmware.py) keeps the rails: the
    firmware's towers, seen from its origin c, are the calibrated rails B_i + (t_x, t_y) to
    1e-12 mm, the switches at the same carriage heights, and every reading the same at the
    same physical nozzle position; nothing is dropped."""
    from pkmcal.io.delta_firmware import exact_rewrite

    rng = np.random.default_rng(11)
    m = DeltaFirmware(radius=105.0, angles_deg=(210.3, 329.8, 90.1), arms=(215.4, 214.8, 215.2),
                      endstops=(250.3, 249.7, 250.9)).machine("m")
    rho = m.params
    rho[PARAM_NAMES.index("radius_b")] = 103.3
    rho[PARAM_NAMES.index("radius_c")] = 106.1
    rho[-3:] = (0.7, -0.4, 12.0)                    # a tool offset: its x, y move the rails, its z cancels
    m = m.with_params(rho)
    fw, dropped = firmware_subset(m)
    assert dropped == [] and fw.origin != (0.0, 0.0)
    f = fw.machine("f")
    c = np.r_[fw.origin, 0.0]

    def rails(machine):
        g = {p: machine.params[[PARAM_NAMES.index(f"{p}_{t}") for t in "abc"]] for p in ("angle", "radius")}
        return g["radius"][:, None] * np.c_[np.cos(g["angle"]), np.sin(g["angle"])] + machine.params[-3:-1]

    np.testing.assert_allclose(rails(f) + c[:2], rails(m), rtol=0, atol=1e-12)
    np.testing.assert_allclose(f.switch_positions(), m.switch_positions() + rho[-1], rtol=0, atol=1e-12)
    p = np.c_[rng.uniform(-60, 60, (40, 2)), rng.uniform(0, 150, 40)]
    np.testing.assert_allclose(f.ik(p - c) - f.reading_reference, m.ik(p) - m.reading_reference, rtol=0, atol=1e-11)
    # leaning rails have no exact form: the mean radius, and the lean and radii listed as dropped
    rho[PARAM_NAMES.index("lean_radial_a")] = 1e-3
    assert exact_rewrite(m.with_params(rho)) is None
    assert {d.name for d in firmware_subset(m.with_params(rho))[1]} >= {"radius_b", "lean_radial_a", "tool.z"}


def test_cli_import_klipper_writes_the_probe_setup(tmp_path):
    """[probe] x_offset, y_offset, z_offset of printer.cfg into the z-probe setup
    (--setup-output), which reads back with the config's offsets."""
    from pathlib import Path

    from click.testing import CliRunner

    from pkmcal.cli.main import cli
    from pkmcal.io.setup_file import read_setup_file

    cfg = Path(__file__).parents[2] / "examples" / "klipper" / "printer.cfg"
    out, setup = tmp_path / "k.yaml", tmp_path / "probe.yaml"
    res = CliRunner().invoke(cli, ["import", "klipper", str(cfg), "-o", str(out), "--setup-output", str(setup)])
    assert res.exit_code == 0, res.output
    assert "probe: [probe] x_offset -2.5, y_offset 18, z_offset 1.25 mm" in res.output
    np.testing.assert_array_equal(read_setup_file(setup).sensor.probe_offset, [-2.5, 18.0, 1.25])
    bare = _write(tmp_path, "bare.cfg", _MAIN)
    res = CliRunner().invoke(cli, ["import", "klipper", bare, "-o", str(tmp_path / "b.yaml"), "--setup-output",
                                   str(tmp_path / "p2.yaml")])
    assert res.exit_code == 2 and "no [probe] or [bltouch] section" in res.output
    assert not (tmp_path / "b.yaml").exists()


def test_outputs_never_overwrite_an_included_file(tmp_path):
    """Issue 25: 'import klipper -o arms.cfg' overwrote a file that printer.cfg includes."""
    from click.testing import CliRunner

    from pkmcal.cli.main import cli

    arms = _write(tmp_path, "arms.cfg", "[stepper_a]\narm_length: 250\n")
    cfg = _write(tmp_path, "printer.cfg", _MAIN + "[include arms.cfg]\n")
    before = (tmp_path / "arms.cfg").read_text()
    run = CliRunner().invoke
    for args in (["import", "klipper", cfg, "-o", arms],
                 ["export", "kossel-mini", "--format", "klipper", "--config", cfg, "-o", arms]):
        res = run(cli, args)
        assert res.exit_code == 2 and "arms.cfg" in res.output, res.output
    assert (tmp_path / "arms.cfg").read_text() == before
